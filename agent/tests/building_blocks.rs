//! The controller's building blocks: BLF terms, command filter limits, delay buffer, RBFNN.

use formation_agent::blf::Barrier;
use formation_agent::command_filter::CommandFilter;
use formation_agent::conversion::thrust_and_attitude;
use formation_agent::delay::{delay_steps, StepHistory};
use formation_agent::rbfnn::Rbfnn;
use formation_config::scenario::CommandFilterSpec;
use nalgebra::Vector3;

#[test]
fn blf_terms_are_finite_and_linear_at_z_zero() {
    let b = Barrier::at(&Vector3::zeros(), 0.065);
    assert_eq!(b.nu, Vector3::zeros());
    assert_eq!(b.sincos_term, Vector3::zeros());
    assert_eq!(b.value, 0.0);
    assert!(!b.crossed);
    // Small z: nu -> z, the sin-cos term -> z/2, V_B -> z^T z / 2 (Remark 4 limit).
    let z = Vector3::new(1e-6, -2e-6, 5e-7);
    let b = Barrier::at(&z, 0.065);
    assert!((b.nu - z).norm() < 1e-12);
    assert!((b.sincos_term - z * 0.5).norm() < 1e-15);
    assert!((b.value - 0.5 * z.norm_squared()).abs() < 1e-20);
}

#[test]
fn blf_matches_the_printed_sin_cos_term_away_from_zero() {
    let c = 0.065;
    let z = Vector3::new(0.02, -0.03, 0.01);
    let b = Barrier::at(&z, c);
    let zz = z.norm_squared();
    let s = std::f64::consts::PI * zz / (2.0 * c * c);
    let printed = z / zz * (c * c / std::f64::consts::PI) * s.sin() * s.cos();
    assert!((b.sincos_term - printed).norm() < 1e-15);
    assert!((b.nu - z / s.cos().powi(2)).norm() < 1e-12);
    assert!((b.value - c * c / std::f64::consts::PI * s.tan()).abs() < 1e-15);
}

#[test]
fn blf_stays_finite_and_reports_a_crossed_barrier() {
    let b = Barrier::at(&Vector3::new(0.07, 0.0, 0.0), 0.065);
    assert!(b.crossed);
    assert!(b.nu.iter().all(|x| x.is_finite()) && b.value.is_finite());
    let inf = Barrier::at(&Vector3::new(0.3, 0.0, 0.0), f64::INFINITY);
    assert!(!inf.crossed && (inf.nu[0] - 0.3).abs() < 1e-15);
}

#[test]
fn command_filter_respects_its_magnitude_and_rate_limits() {
    let spec = CommandFilterSpec {
        natural_frequency_rad_s: 40.0,
        damping: 0.8,
        magnitude_limit: [0.3, 0.3, 1.0],
        rate_limit: [0.5, 0.5, 2.0],
    };
    let mut f = CommandFilter::new(&spec, [0.0; 3]);
    let dt = 1e-3;
    let mut max_rate: f64 = 0.0;
    for _ in 0..5000 {
        f.advance([10.0, -10.0, 0.2], dt);
        let v = f.value();
        assert!(v[0] <= 0.3 + 1e-12 && v[1] >= -0.3 - 1e-12);
        max_rate = max_rate.max(f.derivative()[0].abs());
    }
    assert!(max_rate <= 0.5 + 1e-9, "rate {max_rate}");
    let v = f.value();
    assert!((v[0] - 0.3).abs() < 1e-6 && (v[1] + 0.3).abs() < 1e-6);
    assert!(
        (v[2] - 0.2).abs() < 1e-6,
        "an unlimited channel settles on its input"
    );
}

#[test]
fn delay_buffer_returns_the_exact_step_or_the_newest_before_it() {
    let mut h: StepHistory<u64> = StepHistory::new(8);
    assert_eq!(h.at_or_before(3), None);
    for k in 0..20 {
        h.push(k, k * 10);
    }
    assert!(h.has(19) && h.has(12) && !h.has(11));
    assert_eq!(h.at_or_before(15), Some(150));
    assert_eq!(h.at_or_before(25), Some(190));
    assert_eq!(
        h.at_or_before(2),
        Some(120),
        "older than held: the oldest value"
    );
    assert_eq!(delay_steps(0.0256, 1e-3), 26);
    assert_eq!(delay_steps(0.0254, 1e-3), 25);
    assert_eq!(delay_steps(-1.0, 1e-3), 0);
}

#[test]
fn command_conversion_inverts_the_thrust_direction_of_eq_1() {
    let (m, g) = (0.856, 9.81);
    let u = [0.8, -0.5, 0.3];
    let (t, a) = thrust_and_attitude(u, m, g, 0.0);
    // R_t e3 T/m - g e3 must give back u.
    let axis = formation_config::kinematics::thrust_axis(&Vector3::from(a));
    let acc = axis * (t / m) - Vector3::new(0.0, 0.0, g);
    for k in 0..3 {
        assert!(
            (acc[k] - u[k]).abs() < 1e-12,
            "axis {k}: {} vs {}",
            acc[k],
            u[k]
        );
    }
}

#[test]
fn rbfnn_learns_a_constant_under_the_update_law() {
    let mut nn = Rbfnn::new(10, 1, 20.0, 3.0, 0.35, None, |_, _| 0.0);
    // Drive = target - output: a gradient step on the squared error drives the output to the target.
    let target = [0.7, -0.4, 0.2];
    for _ in 0..20000 {
        let out = nn.evaluate([1.0, 2.0, 3.0], [0.1, 0.0, -0.1]);
        let drive = [target[0] - out[0], target[1] - out[1], target[2] - out[2]];
        nn.update(drive, 10.0, 0.0, 1e-3);
    }
    let out = nn.evaluate([1.0, 2.0, 3.0], [0.1, 0.0, -0.1]);
    for k in 0..3 {
        assert!((out[k] - target[k]).abs() < 1e-3, "axis {k}: {}", out[k]);
    }
}
