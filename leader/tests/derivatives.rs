//! The leader's analytic derivatives agree with finite differences, and the formation is centred.
#![allow(clippy::needless_range_loop)] // per-axis index math, as in the library

use formation_config::protocol::wire::ReferenceFrame;
use formation_config::Scenario;
use formation_leader::Mission;

fn frame(m: &Mission, t: f64) -> ReferenceFrame {
    let mut f = ReferenceFrame::default();
    m.reference(0, t, &mut f);
    f
}

fn check_derivatives(s: &Scenario) {
    let m = Mission::from_scenario(s);
    let h = 1e-5;
    for &t in &[0.0, 0.3, 10.0, 34.9, 35.0, 40.0, 40.01, 45.0, 52.7] {
        let (a, b, c) = (frame(&m, t - h), frame(&m, t), frame(&m, t + h));
        for k in 0..3 {
            let v_fd = (c.p_d[k] - a.p_d[k]) / (2.0 * h);
            let a_fd = (c.v_d[k] - a.v_d[k]) / (2.0 * h);
            assert!(
                (v_fd - b.v_d[k]).abs() < 1e-5 * (1.0 + v_fd.abs()),
                "P_d' axis {k} at t={t}: {v_fd} vs {}",
                b.v_d[k]
            );
            assert!(
                (a_fd - b.a_d[k]).abs() < 1e-4 * (1.0 + a_fd.abs()),
                "P_d'' axis {k} at t={t}: {a_fd} vs {}",
                b.a_d[k]
            );
            for i in 0..s.n_agents() {
                let ov = (c.offset[i][k] - a.offset[i][k]) / (2.0 * h);
                let oa = (c.offset_vel[i][k] - a.offset_vel[i][k]) / (2.0 * h);
                assert!(
                    (ov - b.offset_vel[i][k]).abs() < 1e-5 * (1.0 + ov.abs()),
                    "Delta' agent {i} axis {k} t={t}"
                );
                assert!(
                    (oa - b.offset_acc[i][k]).abs() < 1e-3 * (1.0 + oa.abs()),
                    "Delta'' agent {i} axis {k} t={t}: {oa} vs {}",
                    b.offset_acc[i][k]
                );
            }
        }
    }
}

#[test]
fn leader_and_formation_derivatives_match_finite_differences() {
    check_derivatives(&Scenario::paper());
}

#[test]
fn printed_sharp_phase_changes_also_have_consistent_derivatives() {
    check_derivatives(&Scenario::paper_exact());
}

#[test]
fn offsets_are_centred_and_on_the_ring() {
    let s = Scenario::paper();
    let m = Mission::from_scenario(&s);
    let f = frame(&m, 20.0);
    let mut c = [0.0; 3];
    for i in 0..s.n_agents() {
        let r = (f.offset[i][0].powi(2) + f.offset[i][1].powi(2)).sqrt();
        assert!((r - m.radius(i, 20.0).v).abs() < 1e-12, "radius {r}");
        assert!(
            (r - s.mission.formation.cover_radius_m).abs() < 0.03,
            "radius {r}"
        );
        for k in 0..3 {
            c[k] += f.offset[i][k];
        }
    }
    assert!(c.iter().all(|x| x.abs() < 1e-12));
    // Agent 1 at phase pi/2 before the spin, less the pre-rotation of the printed form w_t (t - T2), which
    // tends to -w_0 / (pi k_w) long before T2 (k_w = spin_onset_sharpness).
    let fm = &s.mission.formation;
    let pre = -fm.spin_rate_rad_s / (std::f64::consts::PI * fm.spin_onset_sharpness);
    let angle = f.offset[0][1].atan2(f.offset[0][0]);
    assert!(
        (angle - (std::f64::consts::FRAC_PI_2 + pre)).abs() < 0.02,
        "angle {angle}"
    );
}

#[test]
fn paper_exact_leader_starts_at_the_origin_and_ours_at_the_initial_centroid() {
    let exact = Mission::from_scenario(&Scenario::paper_exact());
    let ours = Mission::from_scenario(&Scenario::paper());
    let (fe, fo) = (frame(&exact, 0.0), frame(&ours, 0.0));
    assert!(fe.p_d.iter().all(|x| x.abs() < 1e-12));
    assert!((fo.p_d[1] - 15.002).abs() < 1e-3 && fo.p_d[0].abs() < 0.01);
    // Both end up over the target.
    let (fe, fo) = (frame(&exact, 30.0), frame(&ours, 30.0));
    assert!((fe.p_d[0] - fe.target[0]).abs() < 1e-9 && (fo.p_d[1] - fo.target[1]).abs() < 1e-9);
    assert!((fo.p_d[2] - 5.0).abs() < 0.05, "altitude {}", fo.p_d[2]);
}

#[test]
fn concentric_rings_put_each_agent_on_its_own_ring_radius_in_both_phases_and_stay_centred() {
    use formation_config::scenario::FormationRing;
    let mut s = Scenario::paper();
    // 2 agents on a 1 m / 0.5 m ring, 3 on a 3 m / 2 m ring.
    s.mission.formation.rings = vec![
        FormationRing {
            agents: 2,
            cover_radius_m: 1.0,
            enclose_radius_m: 0.5,
            phase_rad: 0.0,
        },
        FormationRing {
            agents: 3,
            cover_radius_m: 3.0,
            enclose_radius_m: 2.0,
            phase_rad: 0.3,
        },
    ];
    check_derivatives(&s);
    let m = Mission::from_scenario(&s);
    for (t, radii) in [
        (20.0, [1.0, 1.0, 3.0, 3.0, 3.0]),
        (58.0, [0.5, 0.5, 2.0, 2.0, 2.0]),
    ] {
        let f = frame(&m, t);
        let mut c = [0.0; 2];
        for i in 0..5 {
            let r = f.offset[i][0].hypot(f.offset[i][1]);
            assert!(
                (r - radii[i]).abs() < 0.03,
                "agent {} at t = {t}: radius {r}",
                i + 1
            );
            for k in 0..2 {
                c[k] += f.offset[i][k];
            }
        }
        assert!(c.iter().all(|x| x.abs() < 1e-12), "centre {c:?}");
    }
}
