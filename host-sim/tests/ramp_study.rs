//! The conveyor-ramp study (`host-sim study ramp`): it measures the core's ramp estimator on
//! the time-varying `conveyor-ramp` scene, reproducibly, and refuses a scene without a ramp.

use host_sim::montecarlo::Setup;
use host_sim::ramp_study;
use host_sim::scene::Scene;

#[test]
fn ramp_study_refuses_a_scene_whose_first_event_is_a_step() {
    let scene = Scene::load("reference-step").unwrap();
    let setup: Setup = "n=2,D=1".parse().unwrap();
    let error = ramp_study::run(&scene, &[setup], &[40.0], 4, 1).unwrap_err();
    assert!(error.to_string().contains("not a ramp"), "{error:#}");
}

#[test]
fn slope_error_at_40_db_is_below_one_percent_and_reproducible() {
    let scene = Scene::load("conveyor-ramp").unwrap();
    let setups: Vec<Setup> = ["n=7,D=4", "n=7,D=4,precision=f32"]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
    let runs = 200;
    let rows = ramp_study::run(&scene, &setups, &[40.0], runs, 7).unwrap();
    let again = ramp_study::run(&scene, &setups, &[40.0], runs, 7).unwrap();
    for (row, repeat) in rows.iter().zip(&again) {
        println!("{row}");
        assert_eq!(row.rms.to_bits(), repeat.rms.to_bits(), "not reproducible");
        assert_eq!(row.valid_runs, runs, "line not determined in every run");
        // The 1,000-run study measures 0.26% RMS (README); over 200 runs the RMS estimate's
        // relative standard deviation is ~5%, so 1% (the goal) fails only if the
        // estimator does.
        assert!(row.rms < ramp_study::GOAL_RELATIVE_RMS, "{row}");
    }
    // f32 on the same data: the slope differs from f64 by far less than the spread.
    let (f64_row, f32_row) = (&rows[0], &rows[1]);
    assert!(
        (f64_row.rms - f32_row.rms).abs() < 0.1 * f64_row.rms,
        "f32 {f32_row} vs f64 {f64_row}"
    );
}
