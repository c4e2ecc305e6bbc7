//! What a node carries from one step to the next.

use nalgebra::RealField;

use crate::message::Gaussian;
use crate::trigger::{Trigger, TriggerState};

/// What a node carries from one step to the next: its fused estimate and its
/// sensor's trigger memory.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct NodeState<T: RealField + Copy, const N: usize, const M: usize> {
    /// Fused estimate (the node's output at the last step, its start at the next).
    pub estimate: Gaussian<T, N>,
    /// Trigger memory of the node's sensor.
    pub trigger: TriggerState<T, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> NodeState<T, N, M> {
    /// A node starting from `estimate` with a fresh trigger.
    pub fn new(estimate: Gaussian<T, N>, trigger: &Trigger<T>) -> Self {
        Self {
            estimate,
            trigger: TriggerState::new(trigger),
        }
    }

    /// The commit phase: the fused estimate and the sensor's new trigger
    /// memory become the node's state.
    #[inline(always)]
    pub(crate) fn commit(&mut self, fused: Gaussian<T, N>, trigger: TriggerState<T, M>) {
        self.estimate = fused;
        self.trigger = trigger;
    }
}
