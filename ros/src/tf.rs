//! A transform tree as tf2 keeps one: each frame has at most one parent, edges from `/tf`
//! (stamped, interpolated) and `/tf_static` (valid at all times), and a lookup of
//! `target_from_source` at a time through the frames' common ancestor. As tf2 does, a time
//! outside an edge's recorded samples is an error (no extrapolation), and so are frames that are
//! not connected or a frame given two parents.

use std::collections::HashMap;

use nalgebra::{Isometry3, Translation3};

/// What a lookup or an insertion can fail with; the message names frames and times.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("tf: {0}")]
pub struct TfError(pub String);

#[derive(Clone, Debug)]
enum Edge {
    Static(Isometry3<f64>),
    /// `parent_from_child` samples in stamp order.
    Dynamic(Vec<(i64, Isometry3<f64>)>),
}

/// The tree: per child frame, its parent and the edge to it.
#[derive(Clone, Debug, Default)]
pub struct TfTree {
    edges: HashMap<String, (String, Edge)>,
}

fn strip(frame: &str) -> &str {
    frame.strip_prefix('/').unwrap_or(frame)
}

/// `a` to `b` by `s` in [0, 1]: translation linear, rotation spherical (tf2's interpolation).
fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let t = a.translation.vector.lerp(&b.translation.vector, s);
    let r = a.rotation.slerp(&b.rotation, s);
    Isometry3::from_parts(Translation3::from(t), r)
}

impl TfTree {
    /// An empty tree.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `parent_from_child` at `stamp_ns` (`is_static`: valid at every time). A child that
    /// already has another parent, or an edge that is static in one message and stamped in
    /// another, is refused.
    pub fn insert(
        &mut self,
        parent: &str,
        child: &str,
        stamp_ns: i64,
        parent_from_child: Isometry3<f64>,
        is_static: bool,
    ) -> Result<(), TfError> {
        let (parent, child) = (strip(parent), strip(child));
        if parent == child || child.is_empty() {
            return Err(TfError(format!("a transform from `{parent}` to itself or to an unnamed frame")));
        }
        match self.edges.get_mut(child) {
            None => {
                let edge = if is_static {
                    Edge::Static(parent_from_child)
                } else {
                    Edge::Dynamic(vec![(stamp_ns, parent_from_child)])
                };
                self.edges.insert(child.to_string(), (parent.to_string(), edge));
            }
            Some((p, _)) if p != parent => {
                return Err(TfError(format!("frame `{child}` has two parents, `{p}` and `{parent}`")));
            }
            Some((_, edge)) => match (edge, is_static) {
                (Edge::Static(t), true) => *t = parent_from_child,
                (Edge::Dynamic(samples), false) => {
                    let at = samples.partition_point(|(s, _)| *s <= stamp_ns);
                    if at > 0 && samples[at - 1].0 == stamp_ns {
                        samples[at - 1].1 = parent_from_child;
                    } else {
                        samples.insert(at, (stamp_ns, parent_from_child));
                    }
                }
                _ => return Err(TfError(format!("`{parent}` -> `{child}` is both static and stamped"))),
            },
        }
        Ok(())
    }

    /// `parent_from_child` of one edge at `stamp_ns`.
    fn edge_at(&self, child: &str, stamp_ns: i64) -> Result<(&str, Isometry3<f64>), TfError> {
        let Some((parent, edge)) = self.edges.get(child) else {
            return Err(TfError(format!("frame `{child}` has no parent")));
        };
        let t = match edge {
            Edge::Static(t) => *t,
            Edge::Dynamic(samples) => {
                let at = samples.partition_point(|(s, _)| *s < stamp_ns);
                match (samples.get(at.wrapping_sub(1)), samples.get(at)) {
                    (_, Some((s, t))) if *s == stamp_ns => *t,
                    (Some((s0, t0)), Some((s1, t1))) => interpolate(t0, t1, (stamp_ns - s0) as f64 / (s1 - s0) as f64),
                    _ => {
                        let (first, last) = (samples.first().map_or(0, |s| s.0), samples.last().map_or(0, |s| s.0));
                        return Err(TfError(format!(
                            "`{parent}` -> `{child}` at {:.6} s: outside its samples, {:.6} to {:.6} s (no extrapolation)",
                            stamp_ns as f64 * 1e-9,
                            first as f64 * 1e-9,
                            last as f64 * 1e-9
                        )));
                    }
                }
            }
        };
        Ok((parent, t))
    }

    /// The frames from `frame` up to its root, each with `frame`-to-it (`ancestor_from_frame`).
    fn chain(&self, frame: &str, stamp_ns: i64) -> Result<Vec<(String, Isometry3<f64>)>, TfError> {
        let mut out = vec![(frame.to_string(), Isometry3::identity())];
        let mut current = frame.to_string();
        while self.edges.contains_key(&current) {
            let (parent, t) = self.edge_at(&current, stamp_ns)?;
            let Some((_, below)) = out.last() else { break };
            let next = t * below;
            if out.iter().any(|(f, _)| f == parent) || out.len() > 10_000 {
                return Err(TfError(format!("a cycle through `{parent}`")));
            }
            current = parent.to_string();
            out.push((current.clone(), next));
        }
        Ok(out)
    }

    /// `target_from_source` at `stamp_ns`, through the two frames' lowest common ancestor.
    pub fn lookup(&self, target: &str, source: &str, stamp_ns: i64) -> Result<Isometry3<f64>, TfError> {
        let (target, source) = (strip(target), strip(source));
        let up_source = self.chain(source, stamp_ns)?;
        let up_target = self.chain(target, stamp_ns)?;
        for (frame, ancestor_from_source) in &up_source {
            if let Some((_, ancestor_from_target)) = up_target.iter().find(|(f, _)| f == frame) {
                return Ok(ancestor_from_target.inverse() * ancestor_from_source);
            }
        }
        Err(TfError(format!(
            "`{target}` and `{source}` are not connected (roots `{}` and `{}`)",
            up_target.last().map_or("", |(f, _)| f.as_str()),
            up_source.last().map_or("", |(f, _)| f.as_str())
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn iso(t: [f64; 3], yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_euler_angles(0.0, 0.0, yaw))
    }

    fn tree() -> TfTree {
        let mut tf = TfTree::new();
        tf.insert("map", "odom", 0, iso([1.0, 0.0, 0.0], 0.0), false).unwrap();
        tf.insert("map", "odom", 2_000_000_000, iso([3.0, 0.0, 0.0], 0.4), false).unwrap();
        tf.insert("/odom", "base", 0, iso([0.0, 1.0, 0.0], 0.2), false).unwrap();
        tf.insert("odom", "base", 2_000_000_000, iso([0.0, 1.0, 0.0], 0.2), false).unwrap();
        tf.insert("base", "camera", 0, iso([0.1, 0.0, 0.5], -0.3), true).unwrap();
        tf.insert("map", "landmark", 0, iso([5.0, 5.0, 0.0], 0.0), true).unwrap();
        tf
    }

    #[test]
    fn chains_compose_and_interpolate_and_invert() {
        let tf = tree();
        let got = tf.lookup("map", "camera", 1_000_000_000).unwrap();
        let want = iso([2.0, 0.0, 0.0], 0.2) * iso([0.0, 1.0, 0.0], 0.2) * iso([0.1, 0.0, 0.5], -0.3);
        assert!((got.to_homogeneous() - want.to_homogeneous()).norm() < 1e-12, "{got} vs {want}");
        // Through the common ancestor `map`, and the inverse direction.
        let l = tf.lookup("landmark", "camera", 1_000_000_000).unwrap();
        let want_l = iso([5.0, 5.0, 0.0], 0.0).inverse() * want;
        assert!((l.to_homogeneous() - want_l.to_homogeneous()).norm() < 1e-12);
        let back = tf.lookup("camera", "landmark", 1_000_000_000).unwrap();
        assert!((back.to_homogeneous() - want_l.inverse().to_homogeneous()).norm() < 1e-12);
    }

    #[test]
    fn refusals_name_the_frames() {
        let mut tf = tree();
        let e = tf.lookup("map", "camera", 3_000_000_000).unwrap_err();
        assert!(e.0.contains("`odom` -> `base` at 3.000000 s") && e.0.contains("no extrapolation"), "{e}");
        tf.insert("elsewhere", "thing", 0, Isometry3::identity(), true).unwrap();
        let e = tf.lookup("map", "thing", 0).unwrap_err();
        assert!(e.0.contains("not connected") && e.0.contains("`elsewhere`"), "{e}");
        let e = tf.insert("other", "camera", 0, Isometry3::identity(), true).unwrap_err();
        assert!(e.0.contains("two parents"), "{e}");
        let e = tf.insert("base", "camera", 5, Isometry3::identity(), false).unwrap_err();
        assert!(e.0.contains("both static and stamped"), "{e}");
        let e = tf.lookup("map", "nowhere", 0).unwrap_err();
        assert!(e.0.contains("not connected"), "{e}");
        assert_eq!(tf.lookup("map", "map", 0).unwrap(), Isometry3::identity());
        tf.insert("loop_b", "loop_a", 0, Isometry3::identity(), true).unwrap();
        tf.insert("loop_a", "loop_b", 0, Isometry3::identity(), true).unwrap();
        let e = tf.lookup("map", "loop_a", 0).unwrap_err();
        assert!(e.0.contains("cycle"), "{e}");
    }
}
