//! Coordinate frames of a ROS 2 recording: the tree of the `/tf` and
//! `/tf_static` transforms, looked up at any stamp.
//!
//! Every `geometry_msgs/msg/TransformStamped` on `/tf` (dynamic) or `/tf_static`
//! (fixed) places its `child_frame_id` in its `header.frame_id` (the parent):
//! a point `p_c` of the child frame is `p_p = R p_c + t` in the parent frame,
//! with `t` the transform's translation and `R` its rotation. Each frame has at
//! most one parent, so the transforms form a forest ([`FrameTree`]); the
//! transform between two frames is the chain through their nearest common
//! ancestor ([`FrameTree::path`]), composed of nalgebra [`Isometry3`]s
//! ([`FrameTree::transform`]).
//!
//! **At a stamp.** A `/tf_static` transform holds at every time (the last one
//! published for a child wins). A `/tf` transform is interpolated at the stamp
//! asked for, between the two samples around it: translation linearly,
//! rotation by spherical linear interpolation (nalgebra's
//! [`Isometry3::try_lerp_slerp`]; two rotations too close for it to define an
//! axis are interpolated linearly and normalised). At a sample's own stamp the
//! sample is used as it is. Outside the span of a `/tf` transform's samples
//! there is no transform (tf2's "extrapolation"): [`FrameTree::transform`]
//! returns `None`, and the replay drops that message and counts it.
//!
//! Quaternions are normalised when read; one whose norm is not within 1e-3 of
//! 1 (or is not finite) is an error naming the topic and frames.
//!
//! ```
//! use edccif_io::frames::FrameTree;
//! use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
//! let mut tree = FrameTree::default();
//! // odom moves along x in map: (0, 0, 0) at t = 0 s, (2, 0, 0) at t = 2 s.
//! let at = |x: f64| Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity());
//! tree.add("/tf", false, "map", "odom", 0, at(0.0))?;
//! tree.add("/tf", false, "map", "odom", 2_000_000_000, at(2.0))?;
//! // a camera mounted 1 m above odom's origin, turned 90° about z
//! let mount = Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.0),
//!                                   UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2));
//! tree.add("/tf_static", true, "odom", "camera", 0, mount)?;
//! tree.finish()?; // sorts the /tf samples: before any lookup
//! let path = tree.path("camera", "map")?;
//! let iso = tree.transform(&path, 1_000_000_000)?.unwrap();
//! // a point 1 m ahead of the camera (its x) is 1 m along map's y, 1 m up, at odom's x = 1
//! let p = iso * Point3::new(1.0, 0.0, 0.0);
//! assert!((p - Point3::new(1.0, 1.0, 1.0)).norm() < 1e-12);
//! assert!(tree.transform(&path, 3_000_000_000)?.is_none()); // after the last /tf sample
//! let e = tree.path("camera", "earth").unwrap_err().to_string();
//! assert!(e.contains("`camera`") && e.contains("`earth`") && e.contains("`map`"), "{e}");
//! # Ok::<(), edccif_io::Error>(())
//! ```

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// One parent → child transform: fixed (`/tf_static`) or sampled over time (`/tf`).
#[derive(Debug, Clone, PartialEq)]
struct Edge {
    parent: String,
    topic: String,
    fixed: bool,
    /// `(stamp ns, child → parent)`, sorted by stamp once [`FrameTree::finish`] ran.
    samples: Vec<(u64, Isometry3<f64>)>,
}

/// The frames of a recording and the transforms between them (see the module
/// documentation).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameTree {
    /// child frame → the transform that places it in its parent.
    edges: BTreeMap<String, Edge>,
    sorted: bool,
}

/// How one frame reaches another: the edges climbed from the source frame to
/// the common ancestor, then those from the target frame (applied inverted).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct FramePath {
    /// The frame the data is in.
    pub from: String,
    /// The frame it is brought into.
    pub to: String,
    /// Child frames of the edges climbed from `from` (each placed in its parent).
    up: Vec<String>,
    /// Child frames of the edges climbed from `to`, applied inverted.
    down: Vec<String>,
}

impl FramePath {
    /// Whether no transform is applied (`from == to`).
    pub fn is_identity(&self) -> bool {
        self.up.is_empty() && self.down.is_empty()
    }
}

/// A transform of a path, for reports: `parent → child (topic, fixed or n samples)`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EdgeInfo {
    /// Parent frame.
    pub parent: String,
    /// Child frame.
    pub child: String,
    /// The topic it came from (`/tf`, `/tf_static`, or `declared` for
    /// [`FrameTree::declare_same`]).
    pub topic: String,
    /// Fixed (`/tf_static`, declared) or interpolated at each stamp (`/tf`).
    pub fixed: bool,
    /// Samples of a `/tf` transform (1 for a fixed one).
    pub samples: usize,
}

fn frame_err(problem: String) -> Error {
    Error::Value {
        what: "frames".into(),
        problem,
    }
}

/// A unit quaternion from a ROS `(x, y, z, w)`, normalised; errors when its norm
/// is not within 1e-3 of 1.
///
/// ```
/// use edccif_io::frames::unit_quaternion;
/// assert!(unit_quaternion([0.0, 0.0, 0.0, 1.0], "q").is_ok());
/// assert!(unit_quaternion([0.0, 0.0, 0.0, 0.0], "q").unwrap_err().to_string().contains("norm"));
/// ```
pub fn unit_quaternion(q: [f64; 4], what: &str) -> Result<UnitQuaternion<f64>> {
    let quat = Quaternion::new(q[3], q[0], q[1], q[2]);
    let norm = quat.norm();
    if !(norm.is_finite() && (norm - 1.0).abs() <= 1e-3) {
        return Err(Error::Value {
            what: what.into(),
            problem: format!(
                "rotation (x, y, z, w) = {q:?} has norm {norm}; expected a unit quaternion (norm within 1e-3 of 1)"
            ),
        });
    }
    Ok(UnitQuaternion::from_quaternion(quat))
}

/// A rigid transform from a ROS translation and `(x, y, z, w)` rotation.
pub fn isometry(t: [f64; 3], q: [f64; 4], what: &str) -> Result<Isometry3<f64>> {
    if !t.iter().all(|v| v.is_finite()) {
        return Err(Error::Value {
            what: what.into(),
            problem: format!("translation {t:?}; expected finite values"),
        });
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        unit_quaternion(q, what)?,
    ))
}

/// `a` to `b` at fraction `s ∈ (0, 1)`: translation linear, rotation slerp
/// (normalised linear interpolation where the rotations are too close for slerp).
/// The slerp's quaternion is normalised again: for rotations a few degrees
/// apart its `sin θ` from `√(1 − cos² θ)` leaves a norm error of ~1e-13.
fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    match a.try_lerp_slerp(b, s, f64::EPSILON) {
        Some(m) => Isometry3::from_parts(
            m.translation,
            UnitQuaternion::new_normalize(m.rotation.into_inner()),
        ),
        None => nlerp(a, b, s),
    }
}

/// Normalised linear interpolation of the rotations (the shorter way), linear
/// of the translations.
fn nlerp(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let t = a.translation.vector.lerp(&b.translation.vector, s);
    let (qa, mut qb) = (a.rotation.coords, b.rotation.coords);
    if qa.dot(&qb) < 0.0 {
        qb = -qb;
    }
    let q = UnitQuaternion::from_quaternion(Quaternion::from(qa.lerp(&qb, s)));
    Isometry3::from_parts(Translation3::from(t), q)
}

impl FrameTree {
    /// Adds one transform of `topic` placing `child` in `parent` at `t_ns`
    /// (`fixed`: from `/tf_static`). A frame placed in two different parents is
    /// an error, as is a frame placed in itself.
    pub fn add(
        &mut self,
        topic: &str,
        fixed: bool,
        parent: &str,
        child: &str,
        t_ns: u64,
        child_to_parent: Isometry3<f64>,
    ) -> Result<()> {
        if parent == child {
            return Err(frame_err(format!(
                "{topic}: a transform places frame `{child}` in itself"
            )));
        }
        match self.edges.get_mut(child) {
            Some(e) if e.parent != parent => Err(frame_err(format!(
                "frame `{child}` has two parents: `{}` ({}) and `{parent}` ({topic}); \
                 a frame has one parent in a tf tree",
                e.parent, e.topic
            ))),
            Some(e) => {
                if e.fixed != fixed {
                    return Err(frame_err(format!(
                        "the transform `{parent}` → `{child}` is on both /tf and /tf_static ({} and {topic})",
                        e.topic
                    )));
                }
                if fixed {
                    // The last one published holds.
                    e.samples = vec![(t_ns, child_to_parent)];
                } else {
                    e.samples.push((t_ns, child_to_parent));
                    self.sorted = false;
                }
                Ok(())
            }
            None => {
                self.edges.insert(
                    child.to_string(),
                    Edge {
                        parent: parent.to_string(),
                        topic: topic.to_string(),
                        fixed,
                        samples: vec![(t_ns, child_to_parent)],
                    },
                );
                self.sorted = false;
                Ok(())
            }
        }
    }

    /// Declares frames `a` and `b` the same (an identity transform placing `a`
    /// in `b`): for recordings whose frames have different names but are one.
    pub fn declare_same(&mut self, a: &str, b: &str) -> Result<()> {
        self.add("declared", true, b, a, 0, Isometry3::identity())
    }

    /// Sorts every `/tf` transform's samples by stamp; two samples of one
    /// transform at one stamp must agree.
    pub fn finish(&mut self) -> Result<()> {
        for (child, e) in &mut self.edges {
            e.samples.sort_by_key(|s| s.0);
            let mut dedup: Vec<(u64, Isometry3<f64>)> = Vec::with_capacity(e.samples.len());
            for s in e.samples.drain(..) {
                match dedup.last() {
                    Some(last) if last.0 == s.0 => {
                        if last.1 != s.1 {
                            return Err(frame_err(format!(
                                "{}: two different transforms `{}` → `{child}` at the stamp {} ns",
                                e.topic, e.parent, s.0
                            )));
                        }
                    }
                    _ => dedup.push(s),
                }
            }
            e.samples = dedup;
        }
        self.sorted = true;
        Ok(())
    }

    /// Whether the tree has no transform.
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// Every frame named by a transform.
    pub fn frames(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .edges
            .iter()
            .flat_map(|(c, e)| [c.clone(), e.parent.clone()])
            .collect();
        v.sort();
        v.dedup();
        v
    }

    /// `frame`, its parent, its parent's parent, … up to its root.
    fn ancestors<'a>(&'a self, frame: &'a str) -> Result<Vec<&'a str>> {
        let mut out = vec![frame];
        let mut cur = frame;
        while let Some(e) = self.edges.get(cur) {
            cur = e.parent.as_str();
            if out.contains(&cur) {
                return Err(frame_err(format!(
                    "the transforms form a loop through frame `{cur}` ({})",
                    out.join(" → ")
                )));
            }
            out.push(cur);
        }
        Ok(out)
    }

    /// How `from` reaches `to`, or an error that names both frames and the
    /// missing link (the two roots no transform connects).
    pub fn path(&self, from: &str, to: &str) -> Result<FramePath> {
        let a = self.ancestors(from)?;
        let b = self.ancestors(to)?;
        let Some((ia, ib)) = a
            .iter()
            .enumerate()
            .find_map(|(i, f)| b.iter().position(|g| g == f).map(|j| (i, j)))
        else {
            let (ra, rb) = (a[a.len() - 1], b[b.len() - 1]);
            let chain = |v: &[&str]| {
                if v.len() == 1 {
                    format!("`{}` has no parent", v[0])
                } else {
                    format!(
                        "`{}` reaches {}",
                        v[0],
                        v[1..]
                            .iter()
                            .map(|f| format!("`{f}`"))
                            .collect::<Vec<_>>()
                            .join(" → ")
                    )
                }
            };
            let known = if self.edges.is_empty() {
                "the recording has no /tf or /tf_static transform".to_string()
            } else {
                format!("frames in /tf and /tf_static: {}", self.frames().join(", "))
            };
            return Err(frame_err(format!(
                "frame `{from}` cannot be brought into frame `{to}`: no transform connects them \
                 ({}; {}); the missing link is a transform between `{ra}` and `{rb}` \
                 ({known}; add it to the recording, declare the frames the same, or choose \
                 another target frame)",
                chain(&a),
                chain(&b)
            )));
        };
        Ok(FramePath {
            from: from.into(),
            to: to.into(),
            up: a[..ia].iter().map(|s| s.to_string()).collect(),
            down: b[..ib].iter().map(|s| s.to_string()).collect(),
        })
    }

    /// The transforms a path applies, in order (from the source frame up, then
    /// down to the target frame), for reports.
    pub fn edges_of(&self, path: &FramePath) -> Vec<EdgeInfo> {
        path.up
            .iter()
            .chain(path.down.iter().rev())
            .filter_map(|c| {
                self.edges.get(c).map(|e| EdgeInfo {
                    parent: e.parent.clone(),
                    child: c.clone(),
                    topic: e.topic.clone(),
                    fixed: e.fixed,
                    samples: e.samples.len(),
                })
            })
            .collect()
    }

    /// One edge's child → parent transform at `t_ns` (see the module docs);
    /// `None` outside a `/tf` transform's span.
    fn edge_at(&self, child: &str, t_ns: u64) -> Result<Option<Isometry3<f64>>> {
        if !self.sorted {
            return Err(frame_err(
                "internal: FrameTree::finish was not called before a lookup".into(),
            ));
        }
        let Some(e) = self.edges.get(child) else {
            return Err(frame_err(format!("no transform places frame `{child}`")));
        };
        if e.fixed {
            return Ok(e.samples.first().map(|s| s.1));
        }
        let s = &e.samples;
        match s.binary_search_by_key(&t_ns, |x| x.0) {
            Ok(i) => Ok(Some(s[i].1)),
            Err(0) => Ok(None),
            Err(i) if i >= s.len() => Ok(None),
            Err(i) => {
                let (t0, a) = s[i - 1];
                let (t1, b) = s[i];
                let frac = (t_ns - t0) as f64 / (t1 - t0) as f64;
                Ok(Some(interpolate(&a, &b, frac)))
            }
        }
    }

    /// The transform taking points of `path.from` into `path.to` at `t_ns`, or
    /// `None` when a `/tf` transform on the path has no sample on both sides
    /// of (or at) the stamp.
    pub fn transform(&self, path: &FramePath, t_ns: u64) -> Result<Option<Isometry3<f64>>> {
        let mut up = Isometry3::identity();
        for c in &path.up {
            match self.edge_at(c, t_ns)? {
                Some(e) => up = e * up,
                None => return Ok(None),
            }
        }
        let mut down = Isometry3::identity();
        for c in &path.down {
            match self.edge_at(c, t_ns)? {
                Some(e) => down = e * down,
                None => return Ok(None),
            }
        }
        Ok(Some(down.inverse() * up))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn slerp_at_the_middle_and_nearly_equal_rotations() {
        let a = Isometry3::identity();
        let b = Isometry3::from_parts(
            Translation3::new(2.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.0),
        );
        let m = interpolate(&a, &b, 0.5);
        assert!((m.rotation.angle() - 0.5).abs() < 1e-15);
        assert!((m.translation.vector.x - 1.0).abs() < 1e-15);
        // Rotations closer than slerp resolves: normalised lerp, no panic.
        let c = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1e-17),
        );
        let m = interpolate(&a, &c, 0.3);
        assert!(m.rotation.angle() < 1e-15);
        // The same rotation with opposite signs (q and −q) interpolates to it.
        let q = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.4);
        let neg = UnitQuaternion::new_unchecked(-q.into_inner());
        let p = interpolate(
            &Isometry3::from_parts(Translation3::identity(), q),
            &Isometry3::from_parts(Translation3::identity(), neg),
            0.5,
        );
        assert!(p.rotation.angle_to(&q) < 1e-12);
    }

    #[test]
    fn two_parents_loops_and_declared_frames() {
        let mut t = FrameTree::default();
        t.add("/tf", false, "map", "odom", 0, Isometry3::identity())
            .unwrap();
        let e = t
            .add("/tf", false, "world", "odom", 0, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(e.contains("two parents") && e.contains("`map`") && e.contains("`world`"));
        let e = t
            .add("/tf_static", true, "map", "odom", 0, Isometry3::identity())
            .unwrap_err()
            .to_string();
        assert!(e.contains("both /tf and /tf_static"), "{e}");
        let mut l = FrameTree::default();
        l.add("/tf_static", true, "a", "b", 0, Isometry3::identity())
            .unwrap();
        l.add("/tf_static", true, "b", "a", 0, Isometry3::identity())
            .unwrap();
        l.finish().unwrap();
        assert!(l.path("a", "c").unwrap_err().to_string().contains("loop"));
        let mut d = FrameTree::default();
        d.declare_same("vicon", "world").unwrap();
        d.finish().unwrap();
        let p = d.path("vicon", "world").unwrap();
        let iso = d.transform(&p, 5).unwrap().unwrap();
        assert_eq!(iso * Point3::new(1.0, 2.0, 3.0), Point3::new(1.0, 2.0, 3.0));
        assert_eq!(d.edges_of(&p)[0].topic, "declared");
    }

    #[test]
    fn a_chain_through_a_common_ancestor() {
        // world ← a (translation), world ← b (rotation): a point of a in b.
        let mut t = FrameTree::default();
        let ta =
            Isometry3::from_parts(Translation3::new(1.0, 0.0, 0.0), UnitQuaternion::identity());
        let rb = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        t.add("/tf_static", true, "world", "a", 0, ta).unwrap();
        t.add("/tf_static", true, "world", "b", 0, rb).unwrap();
        t.finish().unwrap();
        let p = t.path("a", "b").unwrap();
        assert!(!p.is_identity());
        let iso = t.transform(&p, 0).unwrap().unwrap();
        // a's origin is (1, 0, 0) in world, which is (0, −1, 0) in b.
        assert!((iso * Point3::origin() - Point3::new(0.0, -1.0, 0.0)).norm() < 1e-15);
        assert!(t.path("a", "a").unwrap().is_identity());
    }
}
