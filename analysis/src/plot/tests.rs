//! Tests of `formation plot` on synthetic run directories.

use super::{run, Format, PlotArgs, PlotError, Rendered};
use formation_runtime::record::csv::Column;
use std::path::{Path, PathBuf};

/// Every column of docs/formats.md, in the documented order: the recorder's own list.
const HEADER: &[&str] = formation_runtime::record::csv::COLUMNS;

const FIGURES: &[&str] = &[
    "fig05_trajectory_3d.png",
    "fig05_top_view.png",
    "fig06_position_errors.png",
    "fig07_rbfnn_error.png",
    "fig08_attitude.png",
    "fig09_attitude_constraint.png",
    "fig10_rate_constraint.png",
    "fig11_inputs.png",
    "fig12_disturbance_estimate.png",
    "fig13_gamma.png",
    "fig14_delta.png",
    "separation.png",
];

/// A fresh, empty directory under the system temp dir.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("formation-plot-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// One synthetic row: smooth made-up signals with roughly the paper's shapes and magnitudes.
fn row(step: usize, t: f64, i: usize, n: usize, rbfnn: bool) -> Vec<f64> {
    let w = 0.026;
    let (tx, ty) = (15.0 * (w * t).sin(), 15.0 * (w * t).cos());
    let radius = 2.0 - 1.0 * ((t - 35.0).atan() / std::f64::consts::PI + 0.5);
    let spin = if t > 40.0 { 0.8 * (t - 40.0) } else { 0.0 };
    let phase = std::f64::consts::PI / 2.0 + std::f64::consts::TAU * i as f64 / n as f64 + spin;
    let decay = (-0.3 * t).exp();
    let osc = if rbfnn {
        0.0
    } else {
        0.15 * (1.3 * t + i as f64).sin()
    };
    let ex = 2.0 * decay * (0.7 * t + i as f64).cos() + osc;
    let ey = -1.5 * decay * (0.5 * t + i as f64).sin() + osc;
    let ez = 0.8 * decay + 0.5 * osc;
    let pdz =
        5.0 * (1.0 - (-0.3 * t).exp()) - 2.0 * ((t - 45.0).atan() / std::f64::consts::PI + 0.5);
    let (pdx, pdy) = (tx + radius * phase.cos(), ty + radius * phase.sin());
    let (px, py, pz) = (pdx + ex, pdy + ey, pdz + ez);
    let phi_c = 0.05 * (0.4 * t + i as f64).sin() * (1.0 + decay);
    let theta_c = 0.04 * (0.3 * t + 2.0 * i as f64).cos();
    let (phi, theta) = (phi_c + 0.01 * decay, theta_c - 0.01 * decay);
    let att = phi.hypot(theta);
    let att_c = phi_c.hypot(theta_c);
    let rate = 0.2 * (0.9 * t).sin().abs() + 0.05;
    let gamma = [0.9 - 0.1 * (t / 20.0).min(1.0), 0.8, 0.95];
    let delta = [0.05 * (0.2 * t).sin(), 0.1, -0.05];
    let d_norm = 0.05 + 0.02 * (0.5 * t).sin();
    let f = [
        0.5 * (0.3 * t).sin(),
        0.4 * (0.2 * t).cos(),
        0.1 * (0.7 * t).sin(),
    ];
    let fh = |k: usize| f[k] * (1.0 - (-t).exp());
    let mut v = vec![0.0; HEADER.len()];
    let mut set = |name: &str, x: f64| {
        let k = HEADER
            .iter()
            .position(|c| *c == name)
            .expect("known column");
        v[k] = x;
    };
    set("step", step as f64);
    set("t", t);
    set("agent", (i + 1) as f64);
    set("px", px);
    set("py", py);
    set("pz", pz);
    set("phi", phi);
    set("theta", theta);
    set("pdx", pdx);
    set("pdy", pdy);
    set("pdz", pdz);
    set("ex", ex);
    set("ey", ey);
    set("ez", ez);
    set("e_norm", (ex * ex + ey * ey + ez * ez).sqrt());
    set("tx", tx);
    set("ty", ty);
    set("thrust", 8.4 + 0.5 * decay * (3.0 * t).sin());
    set("phi_c", phi_c);
    set("theta_c", theta_c);
    set("att_norm", att);
    set("att_cmd_norm", att_c);
    set("c1_bar", att_c + 0.065);
    set("rate_norm", rate);
    set("alpha_norm", rate * 0.95);
    set("c2_bar", 13.0 * std::f64::consts::PI / 36.0);
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let u = 0.3 * ((1.0 + k as f64) * t + i as f64).sin() * (0.3 + decay);
        set(&format!("u_ac_{axis}"), u);
        set(
            &format!("u_a_{axis}"),
            (u * gamma[k] + delta[k]).clamp(-0.4, 0.4),
        );
        set(&format!("gamma_{axis}"), gamma[k]);
        set(
            &format!("gamma_hat_{axis}"),
            gamma[k] + 0.1 * (-0.2 * t).exp(),
        );
        set(&format!("delta_{axis}"), delta[k]);
        set(
            &format!("delta_hat_{axis}"),
            delta[k] * (1.0 - (-0.5 * t).exp()),
        );
        set(&format!("f_{axis}"), f[k]);
        set(&format!("f_hat_{axis}"), fh(k));
    }
    set("d_norm", d_norm);
    set("d_hat", 0.07 * (1.0 - (-0.4 * t).exp()));
    set("tau", 0.01 * (i + 1) as f64);
    v
}

/// Writes `trajectory.csv` (and `summary.json` if `variant` is given) into `dir`.
fn write_synthetic_run(
    dir: &Path,
    n_agents: usize,
    n_steps: usize,
    dt: f64,
    variant: Option<&str>,
) {
    let mut text = HEADER.join(",");
    text.push('\n');
    for step in 0..n_steps {
        let t = step as f64 * dt;
        for i in 0..n_agents {
            let r = row(step, t, i, n_agents, variant != Some("no-rbfnn"));
            let cells: Vec<String> = r.iter().map(|x| format!("{x}")).collect();
            text.push_str(&cells.join(","));
            text.push('\n');
        }
    }
    std::fs::write(dir.join("trajectory.csv"), text).expect("write csv");
    if let Some(v) = variant {
        let json =
            format!("{{\"scenario\": \"paper\", \"variant\": \"{v}\", \"diverged\": false}}");
        std::fs::write(dir.join("summary.json"), json).expect("write summary");
    }
}

/// Width and height from a PNG's IHDR chunk, after checking the signature.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert!(bytes.len() > 24, "file too short for a PNG");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR", "first chunk is IHDR");
    let be = |k: usize| u32::from_be_bytes([bytes[k], bytes[k + 1], bytes[k + 2], bytes[k + 3]]);
    (be(16), be(20))
}

fn assert_figures(files: &[Rendered], out: &Path) {
    let names: Vec<String> = files
        .iter()
        .map(|f| {
            f.path
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    assert_eq!(names, FIGURES, "the list of written figures");
    for f in files {
        assert_eq!(
            f.path.parent(),
            Some(out),
            "written into the output directory"
        );
        let bytes = std::fs::read(&f.path).expect("figure exists");
        assert_eq!(
            png_size(&bytes),
            (f.width, f.height),
            "{}: IHDR size",
            f.path.display()
        );
        assert!(
            bytes.len() > 20_000,
            "{}: only {} bytes, looks blank",
            f.path.display(),
            bytes.len()
        );
    }
}

#[test]
fn renders_all_paper_figures_from_a_trajectory() {
    let dir = temp_dir("single");
    write_synthetic_run(&dir, 5, 601, 0.1, Some("proposed"));
    let args = PlotArgs {
        dir: dir.clone(),
        ..Default::default()
    };
    let files = run(&args).expect("plot succeeds");
    assert_figures(&files, &dir);
    // FORMATION_PLOT_KEEP=1 keeps the figures for a look.
    if std::env::var_os("FORMATION_PLOT_KEEP").is_some() {
        eprintln!("figures kept in {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn svg_figures_are_well_formed_xml_with_their_labels_as_text() {
    let dir = temp_dir("svg");
    write_synthetic_run(&dir, 3, 301, 0.2, Some("proposed"));
    let files = run(&PlotArgs {
        dir: dir.clone(),
        format: Format::Svg,
        ..Default::default()
    })
    .expect("plot succeeds");
    let names: Vec<String> = files
        .iter()
        .map(|f| f.path.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    let expected: Vec<String> = FIGURES.iter().map(|f| f.replace(".png", ".svg")).collect();
    assert_eq!(names, expected);
    // The text of every <text> element of each figure.
    let mut texts = std::collections::BTreeMap::new();
    for f in &files {
        let xml = std::fs::read_to_string(&f.path).expect("an SVG is UTF-8 text");
        let doc = roxmltree::Document::parse(&xml)
            .unwrap_or_else(|e| panic!("{}: not well-formed XML: {e}", f.path.display()));
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "svg", "{}", f.path.display());
        assert_eq!(root.attribute("width"), Some(f.width.to_string().as_str()));
        assert_eq!(
            root.attribute("height"),
            Some(f.height.to_string().as_str())
        );
        assert!(
            !root.descendants().any(|n| n.has_tag_name("image")),
            "{}: a bitmap inside",
            f.path.display()
        );
        let stem = f.path.file_stem().unwrap().to_string_lossy().into_owned();
        let labels: Vec<String> = root
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| n.text().unwrap_or("").trim().to_string())
            .collect();
        assert!(!labels.is_empty(), "{stem}: no text");
        texts.insert(stem, labels);
    }
    for (stem, label) in [
        ("fig05_trajectory_3d", "quadrotor 1"),
        ("fig05_trajectory_3d", "target path T_g"),
        ("fig09_attitude_constraint", "C1_bar"),
        ("separation", "closest pair"),
        ("fig06_position_errors", "t (s)"),
    ] {
        assert!(
            texts[stem].iter().any(|t| t == label),
            "{stem}.svg lacks the text element {label:?}: {:?}",
            texts[stem]
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn compares_two_variants_into_a_separate_output_directory() {
    let a = temp_dir("proposed");
    let b = temp_dir("no-rbfnn");
    let out = temp_dir("compare-out");
    write_synthetic_run(&a, 3, 301, 0.2, Some("proposed"));
    write_synthetic_run(&b, 3, 301, 0.2, Some("no-rbfnn"));
    let args = PlotArgs {
        dir: a.clone(),
        compare: Some(b.clone()),
        out: Some(out.join("figs")),
        ..Default::default()
    };
    let files = run(&args).expect("plot succeeds");
    assert_figures(&files, &out.join("figs"));
    // Side by side: Fig. 6 is wider than without a comparison.
    let fig6 = files
        .iter()
        .find(|f| f.path.ends_with("fig06_position_errors.png"))
        .expect("fig 6");
    assert!(fig6.width > 1500);
    for d in [a, b, out] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn tolerates_a_missing_summary_and_reordered_columns() {
    let dir = temp_dir("no-summary");
    write_synthetic_run(&dir, 2, 101, 0.5, None);
    // Move the first column (step) to the end of every line: columns are read by name.
    let text = std::fs::read_to_string(dir.join("trajectory.csv")).expect("read");
    let moved: Vec<String> = text
        .lines()
        .map(|l| {
            let (first, rest) = l.split_once(',').expect("comma");
            format!("{rest},{first}")
        })
        .collect();
    std::fs::write(dir.join("trajectory.csv"), moved.join("\n")).expect("write");
    let files = run(&PlotArgs {
        dir: dir.clone(),
        ..Default::default()
    })
    .expect("plot succeeds");
    assert_eq!(files.len(), FIGURES.len());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_directory_is_an_input_error() {
    let err = run(&PlotArgs {
        dir: PathBuf::from("/nonexistent/formation-run"),
        ..Default::default()
    })
    .expect_err("must fail");
    assert!(
        matches!(err, PlotError::Input(ref m) if m.contains("does not exist")),
        "{err}"
    );
}

#[test]
fn missing_csv_is_an_input_error() {
    let dir = temp_dir("empty");
    let err = run(&PlotArgs {
        dir: dir.clone(),
        ..Default::default()
    })
    .expect_err("must fail");
    assert!(
        matches!(err, PlotError::Input(ref m) if m.contains("trajectory.csv")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_column_is_an_input_error_naming_the_column() {
    let dir = temp_dir("no-dhat");
    std::fs::write(dir.join("trajectory.csv"), "t,agent,px\n0,1,0\n").expect("write");
    let err = run(&PlotArgs {
        dir: dir.clone(),
        ..Default::default()
    })
    .expect_err("must fail");
    assert!(
        matches!(err, PlotError::Input(ref m) if m.contains("missing column") && m.contains("d_hat")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_number_is_an_input_error_naming_line_and_column() {
    let dir = temp_dir("bad-number");
    write_synthetic_run(&dir, 1, 3, 0.1, None);
    let text = std::fs::read_to_string(dir.join("trajectory.csv")).expect("read");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let pz = HEADER.iter().position(|c| *c == "pz").expect("pz");
    let mut cells: Vec<String> = lines[2].split(',').map(str::to_string).collect();
    cells[pz] = "abc".into();
    lines[2] = cells.join(",");
    std::fs::write(dir.join("trajectory.csv"), lines.join("\n")).expect("write");
    let err = run(&PlotArgs {
        dir: dir.clone(),
        ..Default::default()
    })
    .expect_err("must fail");
    assert!(
        matches!(err, PlotError::Input(ref m) if m.contains("line 3") && m.contains("'pz'")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_legend_inside_the_data_goes_to_the_corner_with_the_fewest_points() {
    use super::style::emptiest_corner;
    use plotters::prelude::SeriesLabelPosition;
    let (x, y) = ((0.0, 10.0), (0.0, 10.0));
    let size = (0.3, 0.3);
    assert!(matches!(
        emptiest_corner(std::iter::empty(), x, y, size),
        SeriesLabelPosition::UpperRight
    ));
    // Data along the upper and the right edges: the lower left corner is empty.
    let edges = (0..100).flat_map(|k| {
        let v = k as f64 / 10.0;
        [(v, 9.5), (9.5, v)]
    });
    assert!(matches!(
        emptiest_corner(edges, x, y, size),
        SeriesLabelPosition::LowerLeft
    ));
}

#[cfg(feature = "foxglove")]
#[test]
fn a_run_with_its_scenario_gets_the_scene_figure_at_the_chosen_frames() {
    let dir = temp_dir("scene");
    let mut s = formation_config::Scenario::paper();
    s.simulation.duration_s = 2.0;
    formation_runtime::sim::write_resolved_scenario(&s, &dir).expect("scenario.toml");
    formation_runtime::sim::run_in_process(&s, formation_config::Variant::Proposed, &dir)
        .expect("sim");
    let times = vec![0.5, 1.5, 9.0];
    let files = run(&PlotArgs {
        dir: dir.clone(),
        scene_at: times.clone(),
        ..Default::default()
    })
    .expect("plot succeeds");
    let scene = files.last().expect("figures");
    assert_eq!(scene.path.file_name().unwrap(), "scene.png");
    assert_eq!(scene.width, 900 * 3 + 100);
    assert!(
        std::fs::metadata(&scene.path).unwrap().len() > 50_000,
        "looks blank"
    );
    // The first scene frame (every 40 steps) at or after each time; a time after the end is the
    // last frame of the run.
    let scenes = super::scene::load(&dir, &times).expect("scenes");
    let steps: Vec<u64> = scenes.at.iter().map(|(_, sc)| sc.step).collect();
    assert_eq!(steps, vec![520, 1520, 1960]);
    // The scene's poses are the rows of trajectory.csv.
    let tr = formation_runtime::record::table::Trajectory::read(&dir.join("trajectory.csv"))
        .expect("csv");
    let row = tr
        .rows()
        .iter()
        .find(|r| {
            tr.value(r, Column::Step) as u64 == 1520 && tr.value(r, Column::Agent) as u64 == 3
        })
        .expect("row of step 1520, agent 3");
    let p = scenes.at[1].1.agent_translation(3).expect("agent 3's /tf");
    assert_eq!(
        p,
        [
            tr.value(row, Column::Px),
            tr.value(row, Column::Py),
            tr.value(row, Column::Pz)
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn events_compare_draws_one_worst_error_line_per_run_into_its_own_figure() {
    let a = temp_dir("events-compare-a");
    let b = temp_dir("events-compare-b");
    write_synthetic_run(&a, 3, 301, 0.1, Some("proposed"));
    write_synthetic_run(&b, 3, 301, 0.1, Some("proposed"));
    let files = run(&PlotArgs {
        dir: a.clone(),
        events_compare: vec![b.clone()],
        ..Default::default()
    })
    .expect("plot succeeds");
    let f = files
        .iter()
        .find(|f| f.path.ends_with("events_compare.png"))
        .expect("the comparison is written");
    assert!(std::fs::metadata(&f.path).unwrap().len() > 1000);
    let _ = std::fs::remove_dir_all(&a);
    let _ = std::fs::remove_dir_all(&b);
}
