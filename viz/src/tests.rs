//! Scene content, pinned on the paper scenario's geometry and hand-made frames.

use crate::channels::{channels, encode, Encoded, LOG, PLOT, TF};
use crate::frame::{AgentSample, Frame};
use crate::scene::*;
use formation_config::scenario::events::{Event, EventKind};
use formation_config::Scenario;
use foxglove::messages::{FrameTransforms, Log, SceneUpdate};
use foxglove::Decode;

fn frame(s: &Scenario, step: u64, shift: f64) -> Frame {
    let n = s.n_agents();
    Frame {
        step,
        t: step as f64 * s.simulation.dt_s,
        p_d: [shift, 0.0, 5.0],
        target: [shift, 0.0, 0.0],
        slots: (0..n).map(|i| [shift + i as f64, 1.0, 5.0]).collect(),
        agents: (0..n)
            .map(|i| AgentSample {
                position: [shift + i as f64, 0.5, 4.0],
                attitude: [0.1, -0.2, 0.3 * i as f64],
                formation_error_m: 0.5,
                ..AgentSample::default()
            })
            .collect(),
    }
}

#[test]
fn the_quaternion_rotates_like_the_plants_rotation_matrix() {
    for a in [
        [0.0, 0.0, 0.0],
        [0.3, -0.2, 1.1],
        [-1.2, 0.7, -2.9],
        [0.05, 1.3, 3.0],
    ] {
        let r = formation_config::kinematics::rotation(&nalgebra::Vector3::from(a));
        let q = quaternion(a);
        let norm = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
        assert!((norm - 1.0).abs() < 1e-12);
        for v in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.3, -0.4, 2.0]] {
            let want = r * nalgebra::Vector3::from(v);
            let got = rotate(&q, v);
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() < 1e-12,
                    "{a:?} {v:?}: {got:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn the_paper_scene_runs_at_25_hz_on_rows_of_the_csv() {
    let s = Scenario::paper();
    assert_eq!(scene_decimation(&s), 40);
    assert_eq!(scene_decimation(&s) % s.output_decimation(), 0);
}

#[test]
fn each_quadrotor_is_posed_by_tf_and_drawn_in_its_own_frame() {
    let s = Scenario::paper();
    let mut b = SceneBuilder::for_scenario(&s);
    let f = frame(&s, 0, 0.0);
    let scene = b.build(&f);
    assert_eq!(scene.transforms.transforms.len(), 5);
    for (i, tf) in scene.transforms.transforms.iter().enumerate() {
        assert_eq!(tf.parent_frame_id, WORLD_FRAME);
        assert_eq!(tf.child_frame_id, agent_frame(i + 1));
        let p = tf.translation.unwrap();
        assert_eq!([p.x, p.y, p.z], f.agents[i].position);
        assert_eq!(tf.rotation.unwrap(), quaternion(f.agents[i].attitude));
    }
    let bodies: Vec<_> = scene
        .agents
        .entities
        .iter()
        .filter(|e| e.id.starts_with("quad/"))
        .collect();
    assert_eq!(bodies.len(), 5);
    assert!(bodies
        .iter()
        .all(|e| e.frame_locked && e.frame_id.starts_with("agent/")));
    assert_eq!(bodies[0].cylinders.len(), 4, "four rotors");
    // Every update replaces its topic's entities.
    for u in [&scene.agents, &scene.mission, &scene.links, &scene.events] {
        assert_eq!(u.deletions.len(), 1);
        assert_eq!(u.deletions[0].r#type, 1, "delete all");
    }
}

#[test]
fn the_footprint_is_the_sensor_cone_on_the_ground_and_the_disk_the_metric_radius() {
    let s = Scenario::paper();
    let mut b = SceneBuilder::for_scenario(&s);
    let scene = b.build(&frame(&s, 0, 0.0));
    let foot = scene
        .agents
        .entities
        .iter()
        .find(|e| e.id == "footprint/1")
        .unwrap();
    let size = foot.cylinders[0].size.unwrap();
    let want = 2.0 * 4.0 * (s.metrics.sensor_fov_deg.to_radians() / 2.0).tan();
    assert!((size.x - want).abs() < 1e-12, "{} vs {want}", size.x);
    let target = scene
        .mission
        .entities
        .iter()
        .find(|e| e.id == "target")
        .unwrap();
    assert_eq!(
        target.cylinders[0].size.unwrap().x,
        2.0 * s.metrics.target_radius_m
    );
    let slots = scene
        .mission
        .entities
        .iter()
        .find(|e| e.id == "slots")
        .unwrap();
    assert_eq!(slots.spheres.len(), 5);
    assert_eq!(slots.spheres[2].pose.unwrap().position.unwrap().x, 2.0);
}

#[test]
fn the_trail_keeps_the_last_three_seconds() {
    let s = Scenario::paper();
    let mut b = SceneBuilder::for_scenario(&s);
    let dec = scene_decimation(&s);
    let mut last = None;
    for k in 0..200 {
        last = Some(b.build(&frame(&s, k * dec, k as f64 * 0.01)));
    }
    let scene = last.unwrap();
    let trail = scene
        .agents
        .entities
        .iter()
        .find(|e| e.id == "trail/2")
        .unwrap();
    let pts = &trail.lines[0].points;
    assert_eq!(pts.len(), (TRAIL_S * SCENE_RATE_HZ) as usize);
    // The newest point is the current position.
    assert!((pts.last().unwrap().x - (1.0 + 1.99)).abs() < 1e-12);
}

#[test]
fn links_are_up_stale_while_an_end_is_down_and_down_after_link_down() {
    let mut s = Scenario::paper();
    let mut crash = Event::new(1.0, EventKind::Crash);
    crash.agent = Some(3);
    crash.down_s = Some(0.5);
    let mut cut = Event::new(2.0, EventKind::LinkDown);
    cut.agents = Some([1, 2]);
    s.events = vec![crash, cut];
    let b = SceneBuilder::for_scenario(&s);
    let color_of = |k: u64, a: usize, b_: usize| {
        let scene = b.scene(&frame(&s, k, 0.0));
        let g = scene
            .links
            .entities
            .iter()
            .find(|e| e.id == "graph")
            .unwrap();
        let l = &g.lines[0];
        let i = b
            .config()
            .edges
            .iter()
            .position(|&e| e == (a, b_))
            .expect("edge of the paper graph");
        assert_eq!(l.points.len(), 2 * b.config().edges.len());
        l.colors[2 * i]
    };
    let edge_with_3 = *b
        .config()
        .edges
        .iter()
        .find(|e| e.0 == 2 || e.1 == 2)
        .unwrap();
    assert_eq!(
        color_of(500, edge_with_3.0, edge_with_3.1),
        link_color(LinkState::Up)
    );
    assert_eq!(
        color_of(1200, edge_with_3.0, edge_with_3.1),
        link_color(LinkState::Stale)
    );
    assert_eq!(
        color_of(1500, edge_with_3.0, edge_with_3.1),
        link_color(LinkState::Up)
    );
    // The paper graph is the path 1-2-3-4-5: edge {1, 2} is (0, 1).
    assert_eq!(color_of(1999, 0, 1), link_color(LinkState::Up));
    assert_eq!(color_of(2000, 0, 1), link_color(LinkState::Down));
    // The crashed quadrotor is grey while down, coloured again after.
    let rotor = |k: u64| {
        let scene = b.scene(&frame(&s, k, 0.0));
        let q = scene
            .agents
            .entities
            .iter()
            .find(|e| e.id == "quad/3")
            .unwrap();
        q.cylinders[0].color.unwrap()
    };
    assert_ne!(rotor(1200), rotor(500));
    assert_eq!(rotor(1500), rotor(500));
}

#[test]
fn an_event_is_logged_once_at_its_step_and_marked_for_four_seconds() {
    let mut s = Scenario::paper();
    let mut fault = Event::new(1.01, EventKind::Fault);
    fault.agent = Some(2);
    fault.gamma = Some([0.5, 0.5, 0.5]);
    fault.delta = Some([0.0, 0.0, 0.1]);
    s.events = vec![fault];
    let mut b = SceneBuilder::for_scenario(&s);
    let dec = scene_decimation(&s);
    let mut logs = Vec::new();
    let mut marked = Vec::new();
    for j in 0..200 {
        let k = j * dec;
        let scene = b.build(&frame(&s, k, 0.0));
        logs.extend(scene.logs.iter().map(|(step, l)| (k, *step, l.clone())));
        if scene
            .events
            .entities
            .iter()
            .any(|e| e.texts.iter().any(|t| t.text == "fault 2"))
        {
            marked.push(k);
        }
    }
    assert_eq!(logs.len(), 1, "{logs:?}");
    let (frame_step, step, log) = &logs[0];
    assert_eq!(*step, 1010);
    assert_eq!(*frame_step, 1040, "the first frame at or after the event");
    assert_eq!(log.timestamp.unwrap(), timestamp(1010, 0.001));
    assert!(
        log.message.contains("actuator fault of agent 2"),
        "{}",
        log.message
    );
    assert_eq!(marked.first(), Some(&1040));
    assert_eq!(
        marked.last(),
        Some(&5000),
        "the last frame before 1010 + 4000"
    );
}

#[test]
fn encoded_messages_decode_to_the_scene_on_their_channels() {
    let s = Scenario::paper();
    let specs = channels(5);
    assert_eq!(specs.len(), PLOT + 5);
    assert_eq!(specs[TF].schema.name, "foxglove.FrameTransforms");
    assert_eq!(specs[TF].schema.encoding, "protobuf");
    assert_eq!(specs[1].schema.name, "foxglove.SceneUpdate");
    assert_eq!(specs[LOG].schema.name, "foxglove.Log");
    assert_eq!(specs[PLOT + 4].topic, "/agent/5/plot");
    let mut e = Event::new(0.0, EventKind::Crash);
    e.agent = Some(1);
    e.down_s = Some(0.5);
    let mut b = SceneBuilder::new(SceneConfig::from_scenario(&s), &[e]);
    let scene = b.build(&frame(&s, 0, 0.0));
    let mut out: Vec<Encoded> = Vec::new();
    encode(&scene, 0.001, &mut out);
    assert_eq!(out.len(), 5 + 1 + 5);
    let tf = FrameTransforms::decode(&out[0].data[..]).unwrap();
    assert_eq!(tf, scene.transforms);
    let agents = SceneUpdate::decode(&out[1].data[..]).unwrap();
    assert_eq!(agents, scene.agents);
    let log = out.iter().find(|m| m.channel == LOG).unwrap();
    assert!(Log::decode(&log.data[..])
        .unwrap()
        .message
        .contains("crash of agent 1"));
    let plot = out.iter().find(|m| m.channel == PLOT + 2).unwrap();
    let v: serde_json::Value = serde_json::from_slice(&plot.data).unwrap();
    assert_eq!(v["agent"], 3);
    let mut keys: Vec<_> = v.as_object().unwrap().keys().cloned().collect();
    let mut want: Vec<_> = plot_schema()["properties"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    keys.sort();
    want.sort();
    assert_eq!(keys, want);
}

#[test]
fn the_shipped_layout_uses_only_topics_and_fields_the_view_publishes() {
    let layout: serde_json::Value =
        serde_json::from_str(include_str!("../../docs/foxglove/formation.json")).unwrap();
    let specs = channels(5);
    let topics: Vec<&str> = specs.iter().map(|c| c.topic.as_str()).collect();
    let schema = plot_schema();
    let fields = schema["properties"].as_object().unwrap();
    let mut plotted = 0;
    for (id, panel) in layout["configById"].as_object().unwrap() {
        if id.starts_with("3D!") {
            for topic in panel["topics"].as_object().unwrap().keys() {
                assert!(topics.contains(&topic.as_str()), "3D panel topic {topic}");
            }
            assert_eq!(panel["followTf"], WORLD_FRAME);
        }
        for p in panel["paths"].as_array().into_iter().flatten() {
            let path = p["value"].as_str().unwrap();
            let (topic, field) = path.split_once(".").unwrap();
            assert!(topics.contains(&topic), "plot topic {topic}");
            let field = field.split('[').next().unwrap();
            assert!(fields.contains_key(field), "plot field {field}");
            plotted += 1;
        }
        if id.starts_with("Log!") {
            assert_eq!(panel["topicToRender"], "/log");
        }
    }
    assert!(plotted >= 20, "{plotted} plotted series");
    // Every panel of the configuration is placed in the layout tree.
    let tree = layout["layout"].to_string();
    for id in layout["configById"].as_object().unwrap().keys() {
        assert!(
            tree.contains(&format!("\"{id}\"")),
            "{id} is not in the layout"
        );
    }
}

#[test]
fn seen_from_above_the_body_follows_its_pose_and_the_footprint_lies_under_it() {
    use crate::topview::{shapes, Shape};
    let s = Scenario::paper();
    let mut b = SceneBuilder::for_scenario(&s);
    let mut f = frame(&s, 0, 0.0);
    let psi = 0.7;
    f.agents[0].attitude = [0.0, 0.0, psi];
    let scene = b.build(&f);
    let all = shapes(&scene);
    let p = f.agents[0].position;
    let color = crate::topview::rgba(agent_color(1, 1.0));
    // The heading arrow of agent 1 starts at P_1 and points along psi.
    let arrow = all
        .iter()
        .find_map(|s| match s {
            Shape::Polyline {
                points, color: c, ..
            } if *c == color && points.len() == 2 => Some(points.clone()),
            _ => None,
        })
        .expect("the arrow of agent 1");
    assert!((arrow[0][0] - p[0]).abs() < 1e-12 && (arrow[0][1] - p[1]).abs() < 1e-12);
    let (dx, dy) = (arrow[1][0] - arrow[0][0], arrow[1][1] - arrow[0][1]);
    assert!((dy.atan2(dx) - psi).abs() < 1e-9, "{dx} {dy}");
    // Its four rotors sit ARM_M from P_1.
    let rotors: Vec<[f64; 2]> = all
        .iter()
        .filter_map(|s| match s {
            Shape::Polygon {
                points, color: c, ..
            } if c.a == 0.8 && c.r == color.r && c.g == color.g => {
                let n = points.len() as f64;
                Some([
                    points.iter().map(|q| q[0]).sum::<f64>() / n,
                    points.iter().map(|q| q[1]).sum::<f64>() / n,
                ])
            }
            _ => None,
        })
        .collect();
    assert_eq!(rotors.len(), 4);
    for r in rotors {
        let d = (r[0] - p[0]).hypot(r[1] - p[1]);
        assert!((d - ARM_M).abs() < 1e-9, "{d}");
    }
    // Labels come last, ground disks first.
    assert!(matches!(all.last(), Some(Shape::Text { .. })));
    assert!(matches!(all.first(), Some(Shape::Polygon { .. })));
}
