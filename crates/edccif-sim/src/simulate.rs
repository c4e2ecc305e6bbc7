//! Seeded simulation of the truth and of every sensor's measurements
//! (ALGORITHM.md §6). Identical for the same seed on any machine and any number
//! of threads: one ChaCha8 stream per run, drawn in a fixed order (`ξ` of the
//! initial estimate; then per step the process noise, then each node's
//! measurement noise, drawn whether or not the node measures at that step).
//!
//! The scenarios of the typed network ([`Scenario::is_typed`]) are simulated
//! with their typed models; every other scenario with its catalogue models
//! ([`crate::catalogue`]) through [`simulate_models`], which also takes models
//! of one's own (the Python bindings' models). Both give the same numbers for
//! the same models.

use edccif_core::angles::wrap_angle;
use edccif_core::{MeasurementModel, MotionModel};
use nalgebra::{DMatrix, SMatrix, SVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::catalogue::{at_node, with_motion, with_sensor, MotionVisitor, SensorVisitor};
use crate::control::Control;
use crate::error::Result;
use crate::scenario::{MotionSpec, Scenario};

/// One simulated run.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    /// Number of steps `T`.
    pub steps: usize,
    /// Number of nodes `N`.
    pub nodes: usize,
    /// State dimension `n`.
    pub n: usize,
    /// True states `x_1 … x_T`, row-major `(T, n)`.
    pub truth: Vec<f64>,
    /// Measurements `z_k^i`, row-major `(T, Σ m_i)`: per step every node's
    /// `m_i` values in node order (`(T, N, 3)` for the paper's sensors; angles
    /// wrapped; NaN where a node does not measure at that step).
    pub z: Vec<f64>,
    /// Every node's measurement dimension `m_i`.
    pub meas_dims: Vec<usize>,
    /// The run's initial estimate `x̂0 = x₀ + chol(P0) ξ`.
    pub x0_hat: Vec<f64>,
}

/// A square root `L` with `L Lᵀ = A` of a symmetric PSD matrix: Cholesky, or a
/// clamped eigen-decomposition when `A` is only semi-definite (e.g. `q = 0`).
pub fn psd_sqrt<const D: usize>(a: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    if let Some(ch) = a.cholesky() {
        return ch.l();
    }
    let e = DMatrix::from_column_slice(D, D, a.as_slice()).symmetric_eigen();
    let mut l = SMatrix::<f64, D, D>::zeros();
    for j in 0..D {
        let s = e.eigenvalues[j].max(0.0).sqrt();
        for i in 0..D {
            l[(i, j)] = e.eigenvectors[(i, j)] * s;
        }
    }
    l
}

fn normals<const D: usize>(rng: &mut ChaCha8Rng) -> SVector<f64, D> {
    SVector::<f64, D>::from_fn(|_, _| StandardNormal.sample(rng))
}

fn simulate_generic<F: MotionModel<f64, N>, const N: usize>(
    sc: &Scenario,
    motion: &F,
    seed: u64,
    dts: Option<&[f64]>,
    ctl: &Control,
    progress: &Control,
) -> Result<Simulation> {
    let steps = dts.map_or(sc.steps, <[f64]>::len);
    let sensors = sc.sensor_models()?;
    let k = sensors.len();
    check_simulation_size(steps, k, N)?;
    progress.add_total(steps as u64);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x0 = SVector::<f64, N>::from_column_slice(&sc.x0);
    let p0_sqrt = SMatrix::<f64, N, N>::from_diagonal(&SVector::<f64, N>::from_iterator(
        sc.p0_diag.iter().map(|v| v.sqrt()),
    ));
    // Draw order: ξ for x̂0; then per step: process noise, then each sensor's noise.
    let x0_hat = x0 + p0_sqrt * normals::<N>(&mut rng);
    let mut lq = psd_sqrt(&motion.process_noise(sc.dt));
    let lr: Vec<SMatrix<f64, 3, 3>> = sensors
        .iter()
        .map(|s| psd_sqrt(&MeasurementModel::<f64, N, 3>::noise(s)))
        .collect();
    let mut truth = Vec::with_capacity(steps * N);
    let mut z = Vec::with_capacity(steps * k * 3);
    let mut x = x0;
    let mut counted = 0;
    for t in 0..steps {
        if t % 1024 == 0 {
            ctl.check()?;
            progress.advance(if t == 0 { 0 } else { 1024 });
            counted = t;
        }
        let dt = match dts {
            Some(d) => {
                lq = psd_sqrt(&motion.process_noise(d[t]));
                d[t]
            }
            None => sc.dt,
        };
        x = motion.transition(&x, dt) + lq * normals::<N>(&mut rng);
        truth.extend_from_slice(x.as_slice());
        for (s, l) in sensors.iter().zip(&lr) {
            let mut zi = MeasurementModel::<f64, N, 3>::measure(s, &x) + l * normals::<3>(&mut rng);
            for c in 0..3 {
                if MeasurementModel::<f64, N, 3>::is_angle(s, c) {
                    zi[c] = wrap_angle(zi[c]);
                }
            }
            z.extend_from_slice(zi.as_slice());
        }
    }
    progress.advance((steps - counted) as u64);
    Ok(Simulation {
        steps,
        nodes: k,
        n: N,
        truth,
        z,
        meas_dims: vec![3; k],
        x0_hat: x0_hat.as_slice().to_vec(),
    })
}

/// One node's sensor as the simulation draws it: `h(x)` plus a draw of its
/// noise `R` (angles wrapped).
pub trait SimSensor<const N: usize>: Send + Sync {
    /// Measurement dimension `m`.
    fn meas_dim(&self) -> usize;
    /// Appends `h(x) + chol(R) ξ` (`ξ` standard normal from `rng`, `m` draws).
    fn sample(&self, x: &SVector<f64, N>, rng: &mut ChaCha8Rng, out: &mut Vec<f64>);
}

/// A typed sensor `H` of measurement dimension `M` as a [`SimSensor`].
#[derive(Debug, Clone)]
pub struct Sampled<H, const N: usize, const M: usize> {
    sensor: H,
    l: SMatrix<f64, M, M>,
}

impl<H: MeasurementModel<f64, N, M>, const N: usize, const M: usize> Sampled<H, N, M> {
    /// The sensor with the square root of its noise.
    pub fn new(sensor: H) -> Self {
        let l = psd_sqrt(&sensor.noise());
        Self { sensor, l }
    }
}

impl<H, const N: usize, const M: usize> SimSensor<N> for Sampled<H, N, M>
where
    H: MeasurementModel<f64, N, M> + Send + Sync,
{
    fn meas_dim(&self) -> usize {
        M
    }
    fn sample(&self, x: &SVector<f64, N>, rng: &mut ChaCha8Rng, out: &mut Vec<f64>) {
        let mut z = self.sensor.measure(x) + self.l * normals::<M>(rng);
        for c in 0..M {
            if self.sensor.is_angle(c) {
                z[c] = wrap_angle(z[c]);
            }
        }
        out.extend_from_slice(z.as_slice());
    }
}

/// Simulates a run of `sc` with the given models: `motion` (state dimension
/// `N`) and one sensor per node; each node measures at the steps its rate
/// gives ([`Scenario::measures`], NaN elsewhere). `dts`: each step's own time
/// step, as [`simulate_with_dt`] (`None`: the scenario's `dt`, `steps`
/// steps). The draws are those of [`simulate`]: the same models give the same
/// numbers bit for bit.
pub fn simulate_models<const N: usize>(
    sc: &Scenario,
    motion: &dyn MotionModel<f64, N>,
    sensors: &[Box<dyn SimSensor<N>>],
    seed: u64,
    dts: Option<&[f64]>,
) -> Result<Simulation> {
    let k = sensors.len();
    if k != sc.nodes() || sc.x0.len() != N || sc.p0_diag.len() != N {
        return Err(crate::error::Error::Shape {
            what: "models".into(),
            expected: format!(
                "{} sensors and {} states (the scenario's)",
                sc.nodes(),
                sc.x0.len()
            ),
            got: format!("{k} sensors and {N} states"),
        });
    }
    let steps = dts.map_or(sc.steps, <[f64]>::len);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x0 = SVector::<f64, N>::from_column_slice(&sc.x0);
    let p0_sqrt = SMatrix::<f64, N, N>::from_diagonal(&SVector::<f64, N>::from_iterator(
        sc.p0_diag.iter().map(|v| v.sqrt()),
    ));
    let x0_hat = x0 + p0_sqrt * normals::<N>(&mut rng);
    let mut lq = psd_sqrt(&motion.process_noise(sc.dt));
    let meas_dims: Vec<usize> = sensors.iter().map(|s| s.meas_dim()).collect();
    let total: usize = meas_dims.iter().sum();
    let mut truth = Vec::with_capacity(steps * N);
    let mut z = Vec::with_capacity(steps * total);
    let mut x = x0;
    for t in 0..steps {
        let dt = match dts {
            Some(d) => {
                lq = psd_sqrt(&motion.process_noise(d[t]));
                d[t]
            }
            None => sc.dt,
        };
        x = motion.transition(&x, dt) + lq * normals::<N>(&mut rng);
        truth.extend_from_slice(x.as_slice());
        for (i, s) in sensors.iter().enumerate() {
            let from = z.len();
            s.sample(&x, &mut rng, &mut z);
            if !sc.measures(i, t) {
                z[from..].fill(f64::NAN);
            }
        }
    }
    Ok(Simulation {
        steps,
        nodes: k,
        n: N,
        truth,
        z,
        meas_dims,
        x0_hat: x0_hat.as_slice().to_vec(),
    })
}

struct BoxSim;

impl<const N: usize> SensorVisitor<N> for BoxSim {
    type Output = Box<dyn SimSensor<N>>;
    fn visit<const M: usize, H>(self, sensor: H) -> Result<Self::Output>
    where
        H: MeasurementModel<f64, N, M> + Send + Sync + 'static,
    {
        Ok(Box::new(Sampled::<H, N, M>::new(sensor)))
    }
}

/// Every node's sensor of `sc` for the simulation, for state dimension `N`.
pub fn sim_sensors<const N: usize>(sc: &Scenario) -> Result<Vec<Box<dyn SimSensor<N>>>> {
    sc.node_specs()
        .iter()
        .enumerate()
        .map(|(i, n)| with_sensor::<N, _>(sc, &n.sensor, BoxSim).map_err(|e| at_node(e, i)))
        .collect()
}

/// The simulation of a scenario of the model network with its catalogue models.
struct SimulateModels<'a> {
    sc: &'a Scenario,
    seed: u64,
    dts: Option<&'a [f64]>,
}

impl MotionVisitor for SimulateModels<'_> {
    type Output = Simulation;
    fn visit<const N: usize, F>(self, motion: F) -> Result<Simulation>
    where
        F: MotionModel<f64, N> + Send + Sync + 'static,
    {
        let sensors = sim_sensors::<N>(self.sc)?;
        simulate_models::<N>(self.sc, &motion, &sensors, self.seed, self.dts)
    }
}

/// Simulates one run of the scenario with the given seed.
///
/// ```
/// use edccif_sim::{simulate, Scenario};
/// let sc = Scenario::paper(4);
/// let a = simulate(&sc, 7).unwrap();
/// assert_eq!((a.truth.len(), a.z.len(), a.x0_hat.len()), (200 * 7, 200 * 4 * 3, 7));
/// assert_eq!(a, simulate(&sc, 7).unwrap()); // seeded
/// ```
pub fn simulate(sc: &Scenario, seed: u64) -> Result<Simulation> {
    simulate_with_control(sc, seed, None, Control::none())
}

/// Refuses a simulation whose truth `(steps, n)` and measurements
/// `(steps, nodes, 3)` do not fit in the memory available
/// ([`limits::check_memory`](crate::limits::check_memory)).
///
/// ```
/// let e = edccif_sim::simulate::check_simulation_size(1 << 50, 4, 7).unwrap_err().to_string();
/// assert!(e.contains("steps"), "{e}");
/// ```
pub fn check_simulation_size(steps: usize, nodes: usize, n: usize) -> Result<()> {
    let values = crate::limits::product(&[steps, n])
        .saturating_add(crate::limits::product(&[steps, nodes, 3]));
    crate::limits::check_memory(
        || {
            format!(
                "a simulation of steps = {steps} with nodes = {nodes} (truth steps × {n}, measurements steps × nodes × 3)"
            )
        },
        values.saturating_mul(8),
    )
}

/// [`simulate`] (or [`simulate_with_dt`] with `dt`) under a [`Control`]: checked
/// for cancellation every 1024 steps ([`Error::Interrupted`](crate::Error::Interrupted)),
/// counting steps as its progress.
pub fn simulate_with_control(
    sc: &Scenario,
    seed: u64,
    dt: Option<&[f64]>,
    ctl: &Control,
) -> Result<Simulation> {
    simulate_inner(sc, seed, dt, ctl, ctl)
}

/// [`simulate_with_control`] checking `ctl` and counting steps on `progress`.
pub(crate) fn simulate_inner(
    sc: &Scenario,
    seed: u64,
    dt: Option<&[f64]>,
    ctl: &Control,
    progress: &Control,
) -> Result<Simulation> {
    sc.validate()?;
    if let Some(dt) = dt {
        for (i, &v) in dt.iter().enumerate() {
            crate::timestep::check_dt(v, format_args!("dt[{i}]"))?;
        }
    }
    if !sc.is_typed() {
        return with_motion(sc, SimulateModels { sc, seed, dts: dt });
    }
    match sc.motion {
        MotionSpec::CoordinatedTurn { .. } => {
            simulate_generic(sc, &sc.coordinated_turn()?, seed, dt, ctl, progress)
        }
        MotionSpec::ConstantVelocity { .. } => {
            simulate_generic::<_, 6>(sc, &sc.constant_velocity()?, seed, dt, ctl, progress)
        }
        MotionSpec::ConstantAcceleration { .. } => {
            simulate_generic::<_, 9>(sc, &sc.constant_acceleration()?, seed, dt, ctl, progress)
        }
        _ => Err(sc.model_network_error()),
    }
}

/// [`simulate`] with non-uniform time steps: the truth moves `dt[t]` between step
/// `t − 1` and step `t` (`dt[0]` from the start), with the process noise `Q(dt[t])`
/// of that step; `dt.len()` steps. Every `dt[t]` equal to the scenario's `dt` gives
/// [`simulate`] bit for bit (when `dt.len()` is the scenario's step count).
///
/// ```
/// use edccif_sim::{simulate, simulate_with_dt, Scenario};
/// let sc = Scenario::paper(4);
/// let uniform = simulate_with_dt(&sc, 3, &vec![sc.dt; sc.steps]).unwrap();
/// assert_eq!(uniform, simulate(&sc, 3).unwrap());
/// let jittered: Vec<f64> = (0..50).map(|k| 0.05 + 0.01 * (k % 7) as f64).collect();
/// assert_eq!(simulate_with_dt(&sc, 3, &jittered).unwrap().steps, 50);
/// ```
pub fn simulate_with_dt(sc: &Scenario, seed: u64, dt: &[f64]) -> Result<Simulation> {
    simulate_with_control(sc, seed, Some(dt), Control::none())
}
