//! Your own models in a few lines: a 2-D target whose velocity decays towards
//! zero, observed through its ranges to two beacons, tracked by the event-triggered
//! cubature information filter (`cif_predict` + `cif_update`).
//!
//! `cargo run -p edccif-core --example custom_model`

use edccif_core::{
    cif_predict, cif_update, EtOptions, Gaussian, MeasurementModel, MotionModel, Observation,
    Trigger, TriggerState,
};
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// State `[x, y, vx, vy]`; the velocity decays at `rate` (1/s).
struct DampedVelocity {
    rate: f64,
    q: f64,
}

impl MotionModel<f64, 4> for DampedVelocity {
    fn transition(&self, x: &Vector4<f64>, dt: f64) -> Vector4<f64> {
        let k = (-self.rate * dt).exp();
        let g = (1.0 - k) / self.rate;
        Vector4::new(x[0] + g * x[2], x[1] + g * x[3], k * x[2], k * x[3])
    }
    fn process_noise(&self, dt: f64) -> Matrix4<f64> {
        // The constant-velocity Q, close enough for small rate·dt.
        let (a, b, c) = (dt.powi(3) / 3.0, dt * dt / 2.0, dt);
        #[rustfmt::skip]
        let q = Matrix4::new(a, 0.0, b, 0.0,  0.0, a, 0.0, b,  b, 0.0, c, 0.0,  0.0, b, 0.0, c);
        q * self.q
    }
    // The Jacobian (needed by the EKF and the untriggered steps' gain) defaults to
    // finite differences; the batch hook `transition_points` defaults to one call
    // per cubature point.
}

/// Ranges to two beacons, standard deviation `sigma`.
struct TwoBeacons {
    beacons: [Vector2<f64>; 2],
    sigma: f64,
}

impl MeasurementModel<f64, 4, 2> for TwoBeacons {
    fn measure(&self, x: &Vector4<f64>) -> Vector2<f64> {
        let p = Vector2::new(x[0], x[1]);
        Vector2::new((p - self.beacons[0]).norm(), (p - self.beacons[1]).norm())
    }
    fn noise(&self) -> Matrix2<f64> {
        Matrix2::identity() * self.sigma.powi(2)
    }
}

/// Runs 200 steps of 0.1 s; returns the final position error (m) and the share
/// of measurements the send-on-delta trigger sent.
pub fn run() -> Result<(f64, f64), edccif_core::Error> {
    let motion = DampedVelocity { rate: 0.2, q: 0.01 };
    let sensor = TwoBeacons {
        beacons: [Vector2::new(0.0, 0.0), Vector2::new(20.0, 0.0)],
        sigma: 0.05,
    };
    let (dt, steps) = (0.1, 200);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, sensor.sigma).expect("σ > 0");
    let mut truth = Vector4::new(5.0, 8.0, 1.0, 0.5);

    let mut estimate = Gaussian::new(Vector4::new(5.2, 7.9, 0.8, 0.6), Matrix4::identity() * 0.1)?;
    let trigger = Trigger::SendOnDelta { delta: 0.01 };
    let mut trigger_state = TriggerState::new(&trigger);
    let mut sent = 0;
    for _ in 0..steps {
        truth = motion.transition(&truth, dt);
        let z = sensor.measure(&truth) + Vector2::from_fn(|_, _| noise.sample(&mut rng));

        let prior = cif_predict(&motion, dt, &estimate)?;
        let step = cif_update(
            &sensor,
            &prior,
            &Observation::Measured(z),
            &trigger,
            &trigger_state,
            &EtOptions::default(),
        )?;
        trigger_state = step.trigger_state;
        sent += usize::from(step.triggered == Some(true));
        estimate = step.local_posterior().to_gaussian()?;
    }
    let error = (estimate.x.fixed_rows::<2>(0) - truth.fixed_rows::<2>(0)).norm();
    Ok((error, sent as f64 / steps as f64))
}

fn main() -> Result<(), edccif_core::Error> {
    let (error, rate) = run()?;
    println!(
        "final position error {error:.3} m, {:.0} % of measurements sent",
        rate * 100.0
    );
    Ok(())
}
