//! Synthetic gestures: the drags of a handle along a line or an arc, as
//! `dend loadtest` sends them and `examples/drag_sim.rs` replays them
//! without the server (one definition, so that the replay's edit is the
//! load test's).

use std::fmt;
use std::str::FromStr;

/// The path a handle follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DragPath {
    /// A straight line across the mesh's second axis.
    Line,
    /// An arc about the fixed end while the handle turns with it (its
    /// rotation changes along the arc), 60° in all.
    Arc,
}

impl FromStr for DragPath {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "line" => Ok(DragPath::Line),
            "arc" => Ok(DragPath::Arc),
            _ => Err(format!("unknown path {s:?} (expected line or arc)")),
        }
    }
}

impl fmt::Display for DragPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DragPath::Line => "line",
            DragPath::Arc => "arc",
        })
    }
}

/// A gesture's geometry: the path, where the handle is (the high end of
/// the mesh's longest axis) and in how many drags it goes.
#[derive(Debug, Clone, Copy)]
pub struct Gesture {
    /// The path.
    pub kind: DragPath,
    /// The longest axis of the mesh (the handle is at its high end).
    pub axis: usize,
    /// Its extent.
    pub extent: f64,
    /// Drags in the gesture.
    pub drags: u64,
}

/// A drag delta as the WebSocket `drag` message carries it: translation,
/// and rotation as a quaternion `[x, y, z, w]` about the handle's current
/// pivot (none: no rotation).
pub type Delta = ([f64; 3], Option<[f64; 4]>);

impl Gesture {
    /// The delta of drag `j` (0-based) of gesture `g` (0-based): even
    /// gestures go along the path, odd ones back (each delta of the way
    /// along undone, in reverse order: the handle turns back about its
    /// pivot and moves back).
    pub fn delta_of(&self, g: u64, j: u64) -> Delta {
        if g % 2 == 0 {
            return self.delta(j);
        }
        let (t, q) = self.delta(self.drags - 1 - j);
        (t.map(|x| -x), q.map(|[x, y, z, w]| [-x, -y, -z, w]))
    }

    /// The delta of drag `i` (0-based) along the path.
    ///
    /// - `Line`: `0.3 · extent / drags` along axis `k + 1` each drag.
    /// - `Arc`: the handle, at radius `extent` from the fixed end along
    ///   axis `k`, swings by 60° about axis `k + 2` and turns with it: each
    ///   drag rotates it by the step about its own pivot and moves the
    ///   pivot along the arc.
    pub fn delta(&self, i: u64) -> Delta {
        let k = self.axis;
        let n = self.drags.max(1) as f64;
        match self.kind {
            DragPath::Line => {
                let mut t = [0.0; 3];
                t[(k + 1) % 3] = 0.3 * self.extent / n;
                (t, None)
            }
            DragPath::Arc => {
                let total = 60f64.to_radians();
                let step = total / n;
                let at = |j: f64| {
                    let a = step * j;
                    (self.extent * a.cos(), self.extent * a.sin())
                };
                let (x0, y0) = at(i as f64);
                let (x1, y1) = at(i as f64 + 1.0);
                let mut t = [0.0; 3];
                t[k] = x1 - x0;
                t[(k + 1) % 3] = y1 - y0;
                let mut axis = [0.0; 3];
                axis[(k + 2) % 3] = 1.0;
                let (s, c) = (0.5 * step).sin_cos();
                (t, Some([axis[0] * s, axis[1] * s, axis[2] * s, c]))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arc() -> Gesture {
        Gesture {
            kind: DragPath::Arc,
            axis: 1,
            extent: 2.0,
            drags: 40,
        }
    }

    /// The arc's deltas add up to the chord of a 60° arc of radius
    /// `extent` (`extent · (cos 60° − 1, sin 60°)`), and their rotations,
    /// each about axis `k + 2`, to 60° (their half-angles' sines sum, for
    /// rotations about one axis, to the angle's).
    #[test]
    fn the_arc_adds_up_to_a_60_degree_swing() {
        let g = arc();
        let (mut t, mut angle) = ([0.0; 3], 0.0);
        for i in 0..g.drags {
            let (d, q) = g.delta(i);
            for k in 0..3 {
                t[k] += d[k];
            }
            // about axis k + 2 = 0 only
            let [x, y, z, w] = q.expect("the arc turns");
            assert_eq!((y, z), (0.0, 0.0));
            angle += 2.0 * x.atan2(w);
        }
        let a = 60f64.to_radians();
        assert!((t[1] - 2.0 * (a.cos() - 1.0)).abs() < 1e-12, "{t:?}");
        assert!((t[2] - 2.0 * a.sin()).abs() < 1e-12, "{t:?}");
        assert_eq!(t[0], 0.0);
        assert!((angle - a).abs() < 1e-12, "{angle}");
    }

    /// An odd gesture undoes the even one: its deltas, summed, cancel
    /// the way along, and drag `j` back is drag `drags − 1 − j` inverted.
    #[test]
    fn the_way_back_undoes_the_way_along() {
        for kind in [DragPath::Line, DragPath::Arc] {
            let g = Gesture { kind, ..arc() };
            let mut t = [0.0; 3];
            for j in 0..g.drags {
                for gesture in [0, 1] {
                    let (d, _) = g.delta_of(gesture, j);
                    for k in 0..3 {
                        t[k] += d[k];
                    }
                }
                let (along, qa) = g.delta(g.drags - 1 - j);
                let (back, qb) = g.delta_of(1, j);
                assert_eq!(back, along.map(|x| -x));
                if let (Some([x, y, z, w]), Some(b)) = (qa, qb) {
                    assert_eq!(b, [-x, -y, -z, w]);
                }
            }
            assert!(t.iter().all(|x| x.abs() < 1e-12), "{kind}: {t:?}");
        }
    }

    #[test]
    fn paths_parse_and_print_the_same_names() {
        for kind in [DragPath::Line, DragPath::Arc] {
            assert_eq!(kind.to_string().parse::<DragPath>(), Ok(kind));
        }
        assert!("swing".parse::<DragPath>().is_err());
    }
}
