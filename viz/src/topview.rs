//! The scene seen from above: every primitive of a [`Scene`]'s SceneUpdates, placed by its
//! entity's frame (`world`, or `agent/{i}` posed by `/tf`) and its own pose, projected on the
//! x-y plane as flat shapes in world metres. `formation plot`'s `scene` figure draws these, so the
//! figure shows exactly what the messages say.

use crate::scene::{rotate, Scene, WORLD_FRAME};
use foxglove::messages::{line_primitive, Color, Pose, Quaternion, SceneEntity, SceneUpdate};

/// A colour: red, green, blue and alpha, each in [0, 1], as the scene's messages carry it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Rgba {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Alpha (1: opaque).
    pub a: f64,
}

/// The colour of a primitive's message.
pub(crate) fn rgba(c: Color) -> Rgba {
    Rgba {
        r: c.r,
        g: c.g,
        b: c.b,
        a: c.a,
    }
}

/// A flat shape in world x-y coordinates, m.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A filled polygon (disks, spheres, boxes).
    Polygon {
        /// Vertices.
        points: Vec<[f64; 2]>,
        /// Fill colour (with alpha).
        color: Rgba,
    },
    /// A stroked polyline (trails, error lines, arrows).
    Polyline {
        /// Vertices.
        points: Vec<[f64; 2]>,
        /// Colour.
        color: Rgba,
        /// Width, m (the primitive's thickness).
        width_m: f64,
    },
    /// A label.
    Text {
        /// Anchor.
        at: [f64; 2],
        /// Text.
        text: String,
        /// Colour.
        color: Rgba,
        /// Font size, m.
        size_m: f64,
    },
}

/// Vertices of a circle polygon.
const CIRCLE_VERTICES: usize = 48;

/// A rigid transform: position and rotation.
#[derive(Debug, Clone, Copy)]
struct Rigid {
    p: [f64; 3],
    q: Quaternion,
}

impl Rigid {
    fn identity() -> Rigid {
        Rigid {
            p: [0.0; 3],
            q: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        }
    }

    fn of(pose: &Option<Pose>) -> Rigid {
        let Some(pose) = pose else {
            return Rigid::identity();
        };
        let p = pose.position.map_or([0.0; 3], |v| [v.x, v.y, v.z]);
        let q = pose.orientation.unwrap_or(Rigid::identity().q);
        Rigid { p, q }
    }

    fn apply(&self, v: [f64; 3]) -> [f64; 3] {
        let r = rotate(&self.q, v);
        [r[0] + self.p[0], r[1] + self.p[1], r[2] + self.p[2]]
    }

    /// self then `inner` (a pose expressed in self's frame).
    fn then(&self, inner: &Rigid) -> Rigid {
        let q = mul(&self.q, &inner.q);
        Rigid {
            p: self.apply(inner.p),
            q,
        }
    }
}

fn mul(a: &Quaternion, b: &Quaternion) -> Quaternion {
    Quaternion {
        w: a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
        x: a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        y: a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        z: a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
    }
}

fn xy(p: [f64; 3]) -> [f64; 2] {
    [p[0], p[1]]
}

fn circle(c: [f64; 3], r: f64) -> Vec<[f64; 2]> {
    (0..CIRCLE_VERTICES)
        .map(|k| {
            let a = k as f64 / CIRCLE_VERTICES as f64 * std::f64::consts::TAU;
            [c[0] + r * a.cos(), c[1] + r * a.sin()]
        })
        .collect()
}

/// Drawing layer of a shape: ground disks, then lines, markers, bodies, labels.
fn layered(layer: u8, s: Shape, out: &mut Vec<(u8, Shape)>) {
    out.push((layer, s));
}

fn entity_shapes(e: &SceneEntity, frame: &Rigid, out: &mut Vec<(u8, Shape)>) {
    let body = e.frame_id != WORLD_FRAME;
    for c in &e.cylinders {
        let t = frame.then(&Rigid::of(&c.pose));
        let d = c.size.map_or(0.0, |s| s.x.max(s.y));
        let layer = if body { 3 } else { 0 };
        let color = rgba(c.color.unwrap_or_default());
        layered(
            layer,
            Shape::Polygon {
                points: circle(t.p, d / 2.0),
                color,
            },
            out,
        );
    }
    for s in &e.spheres {
        let t = frame.then(&Rigid::of(&s.pose));
        let d = s.size.map_or(0.0, |s| s.x.max(s.y));
        let color = rgba(s.color.unwrap_or_default());
        layered(
            2,
            Shape::Polygon {
                points: circle(t.p, d / 2.0),
                color,
            },
            out,
        );
    }
    for c in &e.cubes {
        let t = frame.then(&Rigid::of(&c.pose));
        let s = c.size.map_or([0.0; 3], |s| [s.x / 2.0, s.y / 2.0, 0.0]);
        let points = [[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]]
            .iter()
            .map(|[a, b]| xy(t.apply([a * s[0], b * s[1], 0.0])))
            .collect();
        layered(
            3,
            Shape::Polygon {
                points,
                color: rgba(c.color.unwrap_or_default()),
            },
            out,
        );
    }
    for l in &e.lines {
        let t = frame.then(&Rigid::of(&l.pose));
        let pts: Vec<[f64; 2]> = l
            .points
            .iter()
            .map(|p| xy(t.apply([p.x, p.y, p.z])))
            .collect();
        let color = l.color.unwrap_or_default();
        if l.r#type == line_primitive::Type::LineList as i32 {
            for (k, pair) in pts.chunks_exact(2).enumerate() {
                let color = l.colors.get(2 * k).copied().unwrap_or(color);
                layered(
                    1,
                    Shape::Polyline {
                        points: pair.to_vec(),
                        color: rgba(color),
                        width_m: l.thickness,
                    },
                    out,
                );
            }
        } else if pts.len() >= 2 {
            layered(
                1,
                Shape::Polyline {
                    points: pts,
                    color: rgba(color),
                    width_m: l.thickness,
                },
                out,
            );
        }
    }
    for a in &e.arrows {
        let t = frame.then(&Rigid::of(&a.pose));
        let tip = t.apply([a.shaft_length + a.head_length, 0.0, 0.0]);
        layered(
            4,
            Shape::Polyline {
                points: vec![xy(t.p), xy(tip)],
                color: rgba(a.color.unwrap_or_default()),
                width_m: a.shaft_diameter,
            },
            out,
        );
    }
    for x in &e.texts {
        let t = frame.then(&Rigid::of(&x.pose));
        layered(
            5,
            Shape::Text {
                at: xy(t.p),
                text: x.text.clone(),
                color: rgba(x.color.unwrap_or_default()),
                size_m: x.font_size,
            },
            out,
        );
    }
}

/// The shapes of `scene` seen from above, in drawing order (ground first, labels last).
pub fn shapes(scene: &Scene) -> Vec<Shape> {
    let frame_of = |id: &str| -> Rigid {
        if id == WORLD_FRAME {
            return Rigid::identity();
        }
        scene
            .transforms
            .transforms
            .iter()
            .find(|t| t.child_frame_id == id)
            .map(|t| Rigid {
                p: t.translation.map_or([0.0; 3], |v| [v.x, v.y, v.z]),
                q: t.rotation.unwrap_or(Rigid::identity().q),
            })
            .unwrap_or_else(Rigid::identity)
    };
    let updates: [&SceneUpdate; 4] = [&scene.mission, &scene.links, &scene.agents, &scene.events];
    let mut out = Vec::new();
    for u in updates {
        for e in &u.entities {
            entity_shapes(e, &frame_of(&e.frame_id), &mut out);
        }
    }
    out.sort_by_key(|(layer, _)| *layer);
    out.into_iter().map(|(_, s)| s).collect()
}
