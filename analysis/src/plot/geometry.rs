//! Coverage geometry and phase times used by the figures, taken from the run's scenario.

use super::Run;
use formation_config::Scenario;

/// Scenario quantities the figures draw (never literals in the drawing code).
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Radius of the target's adjacent area (the disk to cover), m.
    pub target_radius_m: f64,
    /// Half the sensor's angle of view, rad: footprint radius = P_i3 tan(this).
    pub sensor_half_angle_rad: f64,
    /// Safety distance between two quadrotors, m.
    pub safety_distance_m: f64,
    /// Phase changes (time, name): T1 (converge), T2 (spin), T3 (descend).
    pub phases: Vec<(f64, String)>,
    /// Where these values came from (printed to the user).
    pub source: String,
}

impl Geometry {
    /// Geometry of a scenario.
    pub fn from_scenario(s: &Scenario, source: String) -> Geometry {
        let f = &s.mission.formation;
        Geometry {
            target_radius_m: s.metrics.target_radius_m,
            sensor_half_angle_rad: (s.metrics.sensor_fov_deg / 2.0).to_radians(),
            safety_distance_m: s.metrics.safety_distance_m,
            phases: vec![
                (f.t1_s, "T1".into()),
                (f.t2_s, "T2".into()),
                (f.t3_s, "T3".into()),
            ],
            source,
        }
    }

    /// The run's scenario: `DIR/scenario.toml` if present, else the scenario named in
    /// `summary.json`, else the built-in paper scenario.
    pub fn for_run(run: &Run) -> Geometry {
        let file = run.dir.join("scenario.toml");
        if file.is_file() {
            match Scenario::load(&file.to_string_lossy()) {
                Ok(s) => return Geometry::from_scenario(&s, file.display().to_string()),
                Err(e) => eprintln!("warning: {}: {e}; using another source", file.display()),
            }
        }
        if let Some(name) = &run.scenario {
            if let Ok(s) = Scenario::load(name) {
                return Geometry::from_scenario(&s, format!("scenario '{name}'"));
            }
            eprintln!("warning: scenario '{name}' of summary.json is unknown; using the paper scenario's geometry");
        }
        Geometry::from_scenario(&Scenario::paper(), "built-in paper scenario".into())
    }

    /// Footprint radius of a sensor at height `pz`, m.
    pub fn footprint_radius(&self, pz: f64) -> f64 {
        pz.max(0.0) * self.sensor_half_angle_rad.tan()
    }
}
