//! `host-sim bench` measures the estimator on one thread and on two in the same run, each by
//! its own clock: it once printed the two-thread figure as one thread's times two.

mod support;
use host_sim::montecarlo::{throughput, Precision, Setup};
use host_sim::scene::Scene;
use support::{host_sim, run_ok};

#[test]
fn each_thread_count_is_its_own_measurement() {
    let scene = Scene::load("reference-step").unwrap();
    let setup = Setup {
        order: 5,
        decimation: 24,
        forgetting: 1.0,
        precision: Precision::F32,
    };
    let figures = throughput(&scene, &setup, 40, 2000, 1, &[1, 2]).unwrap();
    let counts: Vec<usize> = figures.iter().map(|(threads, _)| *threads).collect();
    assert_eq!(counts, [1, 2]);
    assert!(figures
        .iter()
        .all(|(_, rate)| rate.is_finite() && *rate > 0.0));
    // Two separately timed passes never agree to the last bit with one scaled by two.
    assert_ne!(figures[1].1, 2.0 * figures[0].1);
}

#[test]
fn the_bench_prints_one_and_two_threads_measured() {
    let out = run_ok(host_sim().args(["bench", "--runs", "20", "--samples", "1000"]));
    assert!(out.contains("updates/s on 1 thread ("), "{out}");
    assert!(out.contains("updates/s on 2 threads ("), "{out}");
    assert!(!out.contains("per thread"), "{out}");
}
