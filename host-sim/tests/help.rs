//! What a user reads in `--help` names nothing they cannot see: no issue numbers, no paths
//! into this repository's source tree.

mod support;
use support::{host_sim, run_ok};

#[test]
fn help_has_no_internal_references() {
    let subcommands = [
        "",
        "simulate",
        "estimate",
        "calibrate",
        "montecarlo",
        "table",
        "chart",
        "study",
        "bench",
        "torture",
        "replay",
        "monitor",
    ];
    for subcommand in subcommands {
        let mut command = host_sim();
        if !subcommand.is_empty() {
            command.arg(subcommand);
        }
        let help = run_ok(command.arg("--help"));
        assert!(help.contains("Usage:"), "{subcommand}: {help}");
        let lower = help.to_lowercase();
        let words: Vec<&str> = lower.split_whitespace().collect();
        for pair in words.windows(2) {
            let number = pair[1].trim_start_matches('#');
            assert!(
                !(pair[0].starts_with("issue") && number.starts_with(|c: char| c.is_ascii_digit())),
                "{subcommand}: `{} {}` in\n{help}",
                pair[0],
                pair[1]
            );
        }
        assert!(
            !lower.contains("src/"),
            "{subcommand}: a source path in\n{help}"
        );
    }
}
