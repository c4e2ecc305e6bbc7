//! The local phase: each node's own filter step (`docs/algorithm.md` §3 for the
//! CIF, §5 for the covariance-form filters) and the Cholesky factors of the
//! estimates' covariances it starts from, `LANES` nodes at a time.

use nalgebra::{RealField, SMatrix, SVector};

use crate::config::{Fusion, NetworkConfig, NodeFilter};
use crate::error::{let_ok, Error, Result};
use crate::filters::{
    cif_predict_factored, cif_update_internal, cov_local_factored, EtStep, TriggerOutcome,
};
use crate::lanes;
use crate::linalg::{all_finite, validate_positive};
use crate::message::{Contribution, Gaussian, InfoPair, Observation};
use crate::model::{MeasurementModel, MotionModel};
use crate::trigger::{Trigger, TriggerState};

use super::packets::{LocalEstimate, LocalOutput};
use super::scratch::{AsPhase, PhaseScratch};
use super::state::NodeState;

/// Local step of a node whose trigger runs at the node (`docs/algorithm.md` §3;
/// §5 for the covariance-form filters): predict over `dt`, decide on `obs` with
/// the row's trigger, update (or take the untriggered step). Reads `state`,
/// changes nothing; its output's [`packet`](LocalOutput::packet) is what the
/// node publishes.
///
/// Checks `cfg` ([`NetworkConfig::validate`]) and `dt` (finite, `> 0`).
/// Under consensus or without fusion the CIF's posterior is also formed in
/// covariance form (and must be positive definite).
pub fn node_local<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cfg.validate()?;
    validate_positive(dt, "time step dt", false)?;
    local_output(cfg, &cfg.trigger, motion, dt, sensor, state, obs)
}

/// Whether `trigger` can run at a sensor apart from its node: the sensor must
/// decide without the node's prediction and without random draws the node's
/// silent step would need (always, send-on-delta, dynamic).
pub fn check_sensor_side_trigger<T: RealField + Copy>(trigger: &Trigger<T>) -> Result<()> {
    if trigger.needs_prediction() || trigger.has_silent_update() {
        return Err(Error::InvalidParameter {
            what: "trigger run at the sensor",
            expected: "always, send-on-delta or dynamic (this one needs the node's prediction or \
                       updates on silence)",
        });
    }
    Ok(())
}

/// Local step of a node whose trigger runs at its sensor ([`check_sensor_side_trigger`]):
/// the node only learns whether a measurement arrived. `Some(z)` is a sent
/// measurement (`γ = 1`); `None` is the row's untriggered step with the last
/// received measurement `z_τ` (kept in `state.trigger.last_sent`), or a step
/// without measurement before the first one arrived (or for an always-sending
/// trigger). `triggered` reports whether `z` arrived.
///
/// Fed what [`Trigger::decide`] lets through, this gives the estimates of
/// [`node_local`] on the sensor's measurements bit for bit (the node's trigger
/// memory keeps `z_τ`; a dynamic trigger's `η` lives at the sensor). A sensor
/// outage looks like silence here: it is the untriggered step, not
/// [`Observation::Missing`].
///
/// ```
/// use edccif_core::node::*;
/// use edccif_core::models::{LinearMotion, Position3};
/// use edccif_core::*;
/// use nalgebra::{SMatrix, SVector, Vector3};
///
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 3, 3>::identity(), SMatrix::<f64, 3, 3>::identity() * 1e-3)?;
/// let sensor = Position3::new([0.1; 3])?;
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::identity())?;
/// let state = NodeState::<f64, 3, 3>::new(start, &cfg.trigger);
/// let z = Vector3::new(1.0, 2.0, 3.0);
/// let (sent, _) = cfg.trigger.decide::<_, 3, 3>(&sensor, &state.trigger, &z);
/// assert!(sent);
/// let at_sensor = node_local_received(&cfg, &motion, 0.1, &sensor, &state, Some(&z))?;
/// let at_node = node_local(&cfg, &motion, 0.1, &sensor, &state, &Observation::Measured(z))?;
/// assert_eq!(at_sensor, at_node);
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn node_local_received<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    z: Option<&SVector<T, M>>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cfg.validate()?;
    check_sensor_side_trigger(&cfg.trigger)?;
    validate_positive(dt, "time step dt", false)?;
    let (obs, trigger) = match (z, state.trigger.last_sent, cfg.trigger) {
        (Some(z), _, _) => (Observation::Measured(*z), Trigger::Always),
        (None, _, Trigger::Always) | (None, None, _) => (Observation::Missing, cfg.trigger),
        (None, Some(zt), t) => (Observation::Measured(zt), t),
    };
    let mut out = local_output(cfg, &trigger, motion, dt, sensor, state, &obs)?;
    out.triggered = out.triggered.map(|_| z.is_some());
    Ok(out)
}

/// [`node_local`] writing into a node's [`PhaseScratch`] for a loop over many
/// nodes (see the [module documentation](super)): the local part the fusion
/// phases read, the local posterior in covariance form
/// ([`post`](PhaseScratch::post), when formed), `triggered` and `gated`.
/// Returns the sensor's new trigger memory, which the caller commits with the
/// fused estimate. The same numbers as [`node_local`], bit for bit; under a
/// diffusion fusion the CIF's local posterior pair is left unformed (the
/// adaptation forms it if its guard needs it).
///
/// Checks `cfg` and `dt` as [`node_local`]; on error `out` may hold part of
/// the step.
///
/// ```
/// use edccif_core::node::*;
/// use edccif_core::models::{LinearMotion, Position3};
/// use edccif_core::*;
/// use nalgebra::{SMatrix, SVector, Vector3};
///
/// let motion = LinearMotion::new(
///     SMatrix::<f64, 3, 3>::identity(), SMatrix::<f64, 3, 3>::identity() * 1e-3)?;
/// let sensor = Position3::new([0.1; 3])?;
/// let cfg = NetworkConfig { filter: NodeFilter::Cif, trigger: Trigger::SendOnDelta { delta: 0.04 },
///                           et: EtOptions::default(), fusion: Fusion::DiffusionCi,
///                           rule: FusionRule::CI };
/// let start = Gaussian::new(SVector::<f64, 3>::zeros(), SMatrix::<f64, 3, 3>::identity())?;
/// let state = NodeState::<f64, 3, 3>::new(start, &cfg.trigger);
/// let obs = Observation::Measured(Vector3::new(1.0, 2.0, 3.0));
/// let mut scratch = PhaseScratch::default();
/// let trigger = node_local_into(&cfg, &motion, 0.1, &sensor, &state, &obs, &mut scratch)?;
/// let out = node_local(&cfg, &motion, 0.1, &sensor, &state, &obs)?;
/// assert_eq!((scratch.contribution(), trigger), (&out.local.contribution, out.trigger));
/// # Ok::<(), edccif_core::Error>(())
/// ```
pub fn node_local_into<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
    out: &mut PhaseScratch<T, N>,
) -> Result<TriggerState<T, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    cfg.validate()?;
    validate_positive(dt, "time step dt", false)?;
    out.factored = false;
    local_phase(cfg, &cfg.trigger, motion, dt, sensor, state, obs, out)
}

/// The local phase of one node of a network step, into its scratch, from the
/// factor of its estimate's `P` when the factors phase
/// ([`prefactor_lanes`]) formed one; `cfg` and `dt` already checked.
/// `trigger` is the node's: `cfg.trigger`, or with the node's own threshold
/// ([`StepInputs::deltas`](crate::StepInputs::deltas)).
// The node's trigger beside the row's configuration: a configuration copied
// per node to carry it would cost a copy of every field each step.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn local_phase<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    trigger: &Trigger<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
    out: &mut PhaseScratch<T, N>,
) -> Result<TriggerState<T, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    out.guard_used = false;
    out.gated = false;
    let factor = out.factored.then_some(&out.factor);
    let et = EtStep {
        trigger,
        state: &state.trigger,
        opts: &cfg.et,
    };
    let o = local_into(
        cfg,
        motion,
        dt,
        sensor,
        state,
        factor,
        obs,
        &et,
        &mut out.local,
    )?;
    if let Some(g) = out.local.estimate {
        out.post = g;
    }
    out.triggered = o.triggered;
    out.gated = o.gated;
    Ok(o.trigger_state)
}

/// [`node_local`] and [`node_local_received`] for a configuration and `dt`
/// already checked, with the trigger to decide by (the row's, or `Always` for
/// a measurement a sensor sent); the local posterior pair formed for every
/// fusion, as its packet carries it.
fn local_output<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    trigger: &Trigger<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    obs: &Observation<T, M>,
) -> Result<LocalOutput<T, N, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let et = EtStep {
        trigger,
        state: &state.trigger,
        opts: &cfg.et,
    };
    let mut local = LocalEstimate::empty();
    let o = local_into(cfg, motion, dt, sensor, state, None, obs, &et, &mut local)?;
    if matches!(cfg.fusion, Fusion::DiffusionCi | Fusion::DiffusionConvex) {
        local.posterior = local.prior.updated(&local.contribution);
    }
    Ok(LocalOutput {
        local,
        trigger: o.trigger_state,
        triggered: o.triggered,
        gated: o.gated,
    })
}

/// The local step, the one definition every form above shares: writes the
/// fusion part into `out` (on error `out` may hold part of it) and returns
/// what the trigger did.
///
/// Under a diffusion fusion the CIF's local posterior pair is not formed (the
/// fusion reads it only in the adaptation guard, which forms it from the prior
/// and contribution kept in `out`: [`InfoPair::updated`], the same expression
/// and so the same bits); `out.posterior` then keeps an older value.
///
/// `factor`: the lower Cholesky factor of `state.estimate.p` when the caller
/// has it (the prediction then does not factorise `P` again; the same result
/// and errors, see [`sigma_predict_checked`](crate::sigma)).
#[allow(clippy::too_many_arguments)]
fn local_into<T, F, H, const N: usize, const M: usize>(
    cfg: &NetworkConfig<T>,
    motion: &F,
    dt: T,
    sensor: &H,
    state: &NodeState<T, N, M>,
    factor: Option<&SMatrix<T, N, N>>,
    obs: &Observation<T, M>,
    et: &EtStep<'_, T, M>,
    out: &mut LocalEstimate<T, N>,
) -> Result<TriggerOutcome<T, M>>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    out.fusion = cfg.fusion;
    match cfg.filter {
        NodeFilter::Cif => {
            let_ok!(prior = cif_predict_factored(motion, dt, &state.estimate, factor));
            let_ok!((contribution, outcome) = cif_update_internal(sensor, prior, obs, et));
            out.prior = prior.info();
            out.contribution = *contribution;
            match cfg.fusion {
                Fusion::DiffusionCi | Fusion::DiffusionConvex => out.estimate = None,
                _ => {
                    out.posterior = out.prior.updated(&out.contribution);
                    out.estimate = Some(out.posterior.to_gaussian()?);
                }
            }
            Ok(*outcome)
        }
        NodeFilter::Cov(f) => {
            // The posterior's factor from the definiteness check gives its
            // information form (the same factor, so the same inverse).
            let_ok!(
                (r, factor) =
                    cov_local_factored(&f, motion, dt, sensor, &state.estimate, factor, obs, et)
            );
            out.prior = InfoPair::zeros();
            out.contribution = Contribution::zeros();
            out.posterior = match cfg.fusion {
                Fusion::Local => InfoPair::zeros(),
                _ => r.posterior.info_from_factor(factor)?,
            };
            out.estimate = Some(r.posterior);
            Ok(TriggerOutcome {
                triggered: r.triggered,
                trigger_state: r.trigger_state,
                gated: r.gated,
            })
        }
    }
}

/// The factors phase: the lower Cholesky factors of the estimates' covariances
/// of the nodes in `group` (ascending, at most [`LANES`](crate::lanes)) through
/// [`lanes::cholesky_in_place`] (each lane the factor of the scalar
/// [`cholesky`](crate::linalg::cholesky) bit for bit), written into their
/// scratch with a zero strict upper triangle, as
/// [`Cholesky::l`](nalgebra::Cholesky::l) gives it. A node whose `P` has a
/// non-finite entry or whose factorisation fails gets none (`factored` false):
/// its local phase factorises `P` itself and names the error.
pub(crate) fn prefactor_lanes<'a, T, S, const N: usize>(
    group: &[usize],
    estimate: impl Fn(usize) -> &'a Gaussian<T, N>,
    scratch: &mut [S],
) where
    T: RealField + Copy,
    S: AsRef<PhaseScratch<T, N>> + AsMut<PhaseScratch<T, N>>,
{
    let mut m = lanes::zeros::<T, N>();
    lanes::pad(&mut m, group.len());
    for (l, &i) in group.iter().enumerate() {
        let p = &estimate(i).p;
        for (j, col) in m.iter_mut().enumerate() {
            for (r, e) in col.iter_mut().enumerate().skip(j) {
                e[l] = p[(r, j)];
            }
        }
    }
    let ok = lanes::cholesky_in_place(&mut m);
    for (l, &i) in group.iter().enumerate() {
        let s = scratch[i].phase_mut();
        s.factored = ok[l] && all_finite(&estimate(i).p);
        if s.factored {
            for (j, col) in m.iter().enumerate() {
                for (r, v) in col.iter().enumerate() {
                    s.factor[(r, j)] = if r >= j { v[l] } else { T::zero() };
                }
            }
        }
    }
}
