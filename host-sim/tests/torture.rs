//! `host-sim torture`: the same report on 1 and 2 threads, one run reproduced alone with
//! its trace, and its last line in the documented form.

mod support;
use support::host_sim;

/// The output and whether it exited successfully (it exits non-zero when it found a
/// silent wrong reading).
fn torture(args: &[&str]) -> (String, bool) {
    let output: std::process::Output = host_sim()
        .arg("torture")
        .args(args)
        .output()
        .expect("host-sim runs");
    // It always reports: a run that found wrong readings exits non-zero, but still
    // prints its table.
    assert!(
        !output.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    (
        String::from_utf8(output.stdout).unwrap(),
        output.status.success(),
    )
}

/// `silent wrong readings: W of M shown in N runs` → (W, M, N).
fn last_line(report: &str) -> (u64, u64, u64) {
    let line = report.lines().last().unwrap();
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(&words[..3], ["silent", "wrong", "readings:"], "{line}");
    assert_eq!(
        (words[4], words[6], words[7], words[9]),
        ("of", "shown", "in", "runs")
    );
    (
        words[3].parse().unwrap(),
        words[5].parse().unwrap(),
        words[8].parse().unwrap(),
    )
}

#[test]
fn the_same_report_on_one_and_two_threads_and_exit_status_follows_it() {
    let (one, ok_one) = torture(&["--runs", "6", "--seed", "3", "--threads", "1"]);
    let (two, ok_two) = torture(&["--runs", "6", "--seed", "3", "--threads", "2"]);
    assert_eq!(one, two);
    assert_eq!(ok_one, ok_two);
    let (wrong, shown, runs) = last_line(&one);
    assert_eq!(runs, 6);
    assert!(shown > 100, "{one}");
    assert_eq!(ok_one, wrong == 0, "{one}");
    // Every act drawn appears in the table with its name.
    assert!(one.contains("| boot, empty pan |"), "{one}");
    assert!(one.contains("| all |"), "{one}");
}

#[test]
fn one_run_alone_gives_its_share_and_a_trace_of_truth_and_readings() {
    let trace = support::scratch("torture", "run2.csv");
    let (alone, _) = torture(&[
        "--runs",
        "6",
        "--seed",
        "3",
        "--only-run",
        "2",
        "--trace",
        trace.to_str().unwrap(),
    ]);
    let (_, shown, runs) = last_line(&alone);
    assert_eq!(runs, 1);
    let text = std::fs::read_to_string(&trace).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t_s,truth_low_g,truth_high_g,mass_g,u_g,state,final,act,tare_truth_g,event")
    );
    let readouts: Vec<Vec<&str>> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|f| !f[0].is_empty())
        .collect();
    // One line per 50 ms readout; the run starts on an empty pan at power-up.
    assert!(readouts.len() as u64 >= shown);
    assert_eq!(readouts[0][0], "0.050");
    assert_eq!(readouts[0][1], "0.0000");
    assert_eq!(readouts[0][7], "boot");
    // Shown as settled: stable, empty or final.
    let shown_settled = readouts
        .iter()
        .filter(|f| (matches!(f[5], "stable" | "empty") || f[6] == "1") && !f[3].is_empty())
        .count() as u64;
    assert_eq!(shown_settled, shown);
}

/// The CI-sized torture: 1,000 runs of seed 1, every act and noise kind the
/// torture has, show no reading settled beyond the permissible error (1 of 263,581 at
/// stop 38, run 357 below; about a minute on two cores). The 10,000-run figure is the
/// README's, too long for CI.
#[test]
fn a_thousand_runs_show_nothing_wrong_settled() {
    let (report, ok) = torture(&["--runs", "1000", "--seed", "1"]);
    let (wrong, shown, runs) = last_line(&report);
    assert!(ok && wrong == 0 && runs == 1000 && shown > 0, "{report}");
}

/// Runs of `host-sim torture --runs 1000 --seed 1` that showed wrong readings settled, each
/// for a reason since removed: run 72, a trickle onto 0.3 g on a noisy pan, shown stable
/// 0.09 g behind the load at the fit's first certain reading, before the block test had
/// judged a block (7 of 21 shown); run 401, a trickle shown final 2.5 u off with twice
/// its `u` just within 0.5 e; run 761, a load placed by hand shown stable at its old mass.
/// At stop 32: run 219, a trickle of 0.03 g/s onto the empty pan, shown stable at 0.000 g
/// with 0.052-0.059 g on it (the trend window vouched for the reading by two standard
/// errors of its lines; now by Student's t at z = 2.5). At stop 33: run 639, an item
/// placed by hand on a vibrating floor, shown stable 0.076 g off, part of it the zero's
/// drift under the load (every reading's `u` now carries it). At stop 39: run 357, an item
/// placed by hand on 479 g on a pan with 1.2 g of raw noise, shown stable at the old mass
/// for one line, 0.25 g off (a restless pan's fit now vouches only from 1 s of age).
#[test]
fn runs_that_showed_wrong_readings_settled_show_none() {
    show_none_settled_wrong("1000", &["72", "401", "761", "219", "639", "357"]);
}

/// Runs of `host-sim torture --runs 10000 --seed 1` that showed wrong readings settled at
/// stop 30, each for a reason since removed: runs 4700 and 5430, items of about 1 g put on
/// by hand 1.9 s after 479 g and 341 g were dropped, the cell still ringing by grams (the
/// raw tests allowed for it; the residual motion test sees through it), shown stable 0.72
/// and 0.66 g off; run 9291, an arriving item's estimate jumping out of its band while the
/// reading stayed final, 0.21 g off. At stop 31: runs 2371 and 4912, trickles of about
/// 0.04-0.05 g/s begun 1.7 and 2.5 s after a removal, on pans with 0.86 and 0.94 g of raw
/// noise, shown `Empty` 0.05-0.07 g behind before any test could see the slope
/// (the trend window now vouches for a settled reading). At stop 32: runs 9139 and 8837,
/// trickles onto the empty pan (0.85 g of raw noise in 9139) shown `Empty` 0.05-0.06 g
/// behind, the window's lines taken within two standard errors (Student's t at z = 2.5
/// now, for each line's degrees of freedom). At stop 33: runs 5119 and 2486, 18 and 12
/// lines shown settled 0.05-0.07 g off on zeros that had drifted 0.02-0.03 g under a
/// load for two minutes (every reading's `u` now carries the zero's drift since it was
/// last seen). At stop 39, on restless pans (a fit now vouches only from 1 s of age, not
/// 0.5 s): runs 2062 and 9054, items placed by hand on 456 g and 367 g, shown stable
/// 0.35 g and 0.22 g off; run 3581, a fit 0.5 s old on a vibrating floor, 2.14 g shown
/// 0.054 g off with u = 0.010 g; run 9324, a load set down on a vibrating floor. Also at
/// stop 39: runs 8655 and 8359, trickles shown stable 0.05-0.06 g behind, and 2072 and
/// 7177, a small addition and a removal by hand seen a line late (the trend window's lines
/// were taken to the newest block's mean, half a block old, though they vouch until the
/// next block ends; now to that end). At stop 41: runs 1490 and 1718, trickles begun
/// within a second of a removal on floors vibrating by 0.2-0.3 g, shown empty or stable
/// 0.05-0.06 g behind: the trend window skipped the 1.5 s after the removal whatever the
/// ringing and said nothing meanwhile; it now takes blocks once a block rings no more
/// than the pan did on settled runs. At stop 42: run 4278, a 0.43 g load lifted off by
/// hand at 2 g/s on a pan with 0.17 g of raw noise, shown stable 0.06 g above the truth:
/// the noise alone measured as a ringing of 0.1 g, which the block in progress's test
/// allowed (it now takes the ringing net of the noise's own scatter). (Run 4912 of stop
/// 31: below.)
#[test]
fn runs_of_ten_thousand_that_showed_wrong_readings_settled_show_none() {
    show_none_settled_wrong(
        "10000",
        &[
            "4700", "5430", "9291", "2371", "9139", "8837", "5119", "2486", "2062", "9054", "3581",
            "9324", "8655", "8359", "2072", "7177", "1490", "1718", "4278",
        ],
    );
}

/// Run 4912 of `host-sim torture --runs 10000 --seed 1` (above, stop 31: a trickle on a
/// pan with 0.94 g of raw noise shown `Empty` behind it): since stop 41 it shows nothing
/// settled at all, the trend window taking blocks soon after each change and its young
/// lines unable to vouch for 0.05 g on that pan. Nothing wrong may be shown; that it
/// shows nothing is the price, said here rather than hidden by leaving the run out.
#[test]
fn a_trickle_on_the_noisiest_pan_shows_nothing_wrong() {
    let (report, ok) = torture(&["--runs", "10000", "--seed", "1", "--only-run", "4912"]);
    let (wrong, _, runs) = last_line(&report);
    assert!(ok && wrong == 0 && runs == 1, "{report}");
}

/// Run 7156 of `host-sim torture --runs 10000 --seed 1`: a load at rest on a floor
/// vibrating so that the change tests alarmed every few tenths of a second, 85 runs in
/// 12 s; a fit 0.1 s old showed 467.49 g final and stable, 0.28 g off with u = 0.013 g
/// (stop 38). Run 601 of 1000: a fresh fit on a vibrating floor, shown stable beyond the
/// permissible error. A restless pan's fit now vouches only from 1 s of age, which no run
/// on either pan reaches: nothing wrong is shown (and nothing settled).
#[test]
fn restless_vibrating_pans_show_nothing_wrong() {
    for (of, run) in [("10000", "7156"), ("1000", "601")] {
        let (report, ok) = torture(&["--runs", of, "--seed", "1", "--only-run", run]);
        let (wrong, _, runs) = last_line(&report);
        assert!(ok && wrong == 0 && runs == 1, "run {run} of {of}: {report}");
    }
}

/// Each of `runs` of `host-sim torture --runs <of> --seed 1`, alone, shows readings settled
/// and none of them wrong.
fn show_none_settled_wrong(of: &str, runs: &[&str]) {
    for run in runs {
        let (report, ok) = torture(&["--runs", of, "--seed", "1", "--only-run", run]);
        let (wrong, shown, _) = last_line(&report);
        assert!(ok && wrong == 0 && shown > 0, "run {run} of {of}: {report}");
    }
}
