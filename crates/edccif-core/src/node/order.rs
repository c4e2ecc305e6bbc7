//! The order of a node's sums: its own term among the received ones at its
//! index, as the network step sums over each closed neighbourhood.

use nalgebra::RealField;

use crate::error::{Error, Result};

/// The received items `(sender, weight, packet)` with the node's own
/// `(weight, packet)` inserted before the first sender above `me`: the
/// ascending-index order of the network step when the senders ascend.
pub(super) struct WithOwn<'a, I, P, T> {
    received: I,
    me: usize,
    own: Option<(T, &'a P)>,
    held: Option<(T, &'a P)>,
    from_self: bool,
}

impl<'a, I, P, T> Iterator for WithOwn<'a, I, P, T>
where
    I: Iterator<Item = (usize, T, &'a P)>,
{
    type Item = (T, &'a P);
    fn next(&mut self) -> Option<Self::Item> {
        if let Some(h) = self.held.take() {
            return Some(h);
        }
        match self.received.next() {
            Some((j, w, p)) => {
                self.from_self |= j == self.me;
                if j > self.me {
                    if let Some(own) = self.own.take() {
                        self.held = Some((w, p));
                        return Some(own);
                    }
                }
                Some((w, p))
            }
            None => self.own.take(),
        }
    }
}

/// Runs `combine` over the node's own term and the received ones in order;
/// rejects a packet that claims to come from the node itself.
pub(super) fn with_own<'a, T, P, I, R>(
    me: usize,
    own: (T, &'a P),
    received: I,
    combine: impl FnOnce(&mut WithOwn<'a, I::IntoIter, P, T>) -> Result<R>,
) -> Result<R>
where
    T: RealField + Copy,
    I: IntoIterator<Item = (usize, T, &'a P)>,
{
    let mut items = WithOwn {
        received: received.into_iter(),
        me,
        own: Some(own),
        held: None,
        from_self: false,
    };
    let r = combine(&mut items);
    if items.from_self {
        return Err(Error::InvalidParameter {
            what: "received packet",
            expected: "a sender other than the node itself",
        });
    }
    r
}
