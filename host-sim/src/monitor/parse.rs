//! The readings a monitor takes: any line the boards or host-sim write with a mass in it.

use estimator_core::weighing::console::Unit;

/// One reading, in grams and seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct MonitorReading {
    /// Time, s (since boot, or in the recording).
    pub t_s: f64,
    /// The mass shown, g.
    pub mass_g: Option<f64>,
    /// Its standard uncertainty, g.
    pub u_g: Option<f64>,
    /// The state as the console names it (`empty`, `estimating`, `stable`, `invalid:…`).
    pub state: String,
    /// The reading is final.
    pub is_final: bool,
}

/// The reading a line carries, if any. Three forms are read:
/// - the console's `R t=… mass=… u=… unit=… state=… final=…` (any unit; `-` for none);
/// - the firmware's log line `readout sample=… mass_g=… [u_g=…] state=… …` (RTT through
///   probe-rs, or QEMU's semihosting through `cargo xtask`), timed by `sample_rate_hz`;
/// - a row of `host-sim replay`: `t_s,mass_g,u_g,state,final`.
pub fn parse_line(line: &str, sample_rate_hz: f64) -> Option<MonitorReading> {
    let line = line.trim();
    if let Some(rest) = line.strip_prefix("R ") {
        return console_line(rest);
    }
    if let Some(at) = line.find("readout ") {
        return firmware_line(&line[at + "readout ".len()..], sample_rate_hz);
    }
    replay_row(line)
}

fn console_line(rest: &str) -> Option<MonitorReading> {
    let (mut t, mut mass, mut u, mut unit, mut state, mut fin) =
        (None, None, None, None, None, None);
    for field in rest.split_whitespace() {
        let (key, value) = field.split_once('=')?;
        match key {
            "t" => t = value.parse::<f64>().ok(),
            "mass" => mass = Some(optional(value)?),
            "u" => u = Some(optional(value)?),
            "unit" => unit = Unit::from_name(value),
            "state" => state = Some(value.to_string()),
            "final" => fin = Some(value == "1"),
            _ => {}
        }
    }
    let grams = f64::from(unit?.grams());
    Some(MonitorReading {
        t_s: t?,
        mass_g: mass?.map(|m| m * grams),
        u_g: u.flatten().map(|u| u * grams),
        state: state?,
        is_final: fin.unwrap_or(false),
    })
}

fn firmware_line(rest: &str, sample_rate_hz: f64) -> Option<MonitorReading> {
    let (mut sample, mut mass, mut u, mut state, mut fin) = (None, None, None, None, false);
    for field in rest.split_whitespace() {
        let Some((key, value)) = field.split_once('=') else {
            continue;
        };
        match key {
            "sample" => sample = value.parse::<f64>().ok(),
            "mass_g" => {
                mass = Some(if value == "none" {
                    None
                } else {
                    Some(value.parse().ok()?)
                })
            }
            "u_g" => {
                u = if value == "none" {
                    None
                } else {
                    value.parse().ok()
                }
            }
            "state" => state = Some(firmware_state(value)),
            "final" => fin = value == "1" || value == "true",
            _ => {}
        }
    }
    Some(MonitorReading {
        t_s: sample? / sample_rate_hz,
        mass_g: mass?,
        u_g: u,
        state: state?,
        is_final: fin,
    })
}

/// The firmware logs states as Rust names them (`Stable`, `Invalid(Saturated)`): the
/// console's words instead.
fn firmware_state(value: &str) -> String {
    match value.strip_prefix("Invalid(") {
        Some(reason) => {
            let reason = reason
                .trim_end_matches(')')
                .trim_start_matches("Estimator(");
            format!("invalid:{}", snake(reason))
        }
        None => value.to_ascii_lowercase(),
    }
}

fn snake(name: &str) -> String {
    let mut out = String::new();
    for (index, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() && index > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_lowercase());
    }
    out
}

fn replay_row(line: &str) -> Option<MonitorReading> {
    let fields: Vec<&str> = line.split(',').collect();
    let [t, mass, u, state, fin] = fields.as_slice() else {
        return None;
    };
    Some(MonitorReading {
        t_s: t.parse().ok()?,
        mass_g: if mass.is_empty() {
            None
        } else {
            Some(mass.parse().ok()?)
        },
        u_g: if u.is_empty() {
            None
        } else {
            Some(u.parse().ok()?)
        },
        state: state.to_string(),
        is_final: *fin == "1",
    })
}

/// `-` is none; anything else must be a number.
fn optional(value: &str) -> Option<Option<f64>> {
    if value == "-" {
        Some(None)
    } else {
        value.parse().ok().map(Some)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_forms_give_the_same_reading() {
        let console = parse_line(
            "R t=0.450 mass=0.13832 u=0.000012 unit=kg state=stable final=1",
            4000.0,
        )
        .unwrap();
        assert!((console.mass_g.unwrap() - 138.32).abs() < 1e-9);
        assert!((console.u_g.unwrap() - 0.012).abs() < 1e-12);
        assert_eq!(
            (console.t_s, console.state.as_str(), console.is_final),
            (0.45, "stable", true)
        );
        let firmware = parse_line(
            "0.450000 INFO readout sample=1800 mass_g=138.32 state=Stable since=600 dropped=0 changes=1",
            4000.0,
        )
        .unwrap();
        assert_eq!(firmware.t_s, 0.45);
        assert_eq!(firmware.mass_g, Some(138.32));
        assert_eq!(firmware.state, "stable");
        let replay = parse_line("0.45,138.32,0.012,stable,1", 4000.0).unwrap();
        assert_eq!(
            (replay.mass_g, replay.u_g, replay.is_final),
            (Some(138.32), Some(0.012), true)
        );
    }

    #[test]
    fn no_mass_invalid_states_and_other_lines() {
        let line = parse_line(
            "readout sample=400 mass_g=none state=Invalid(Estimator(IllConditioned)) since=2 dropped=0 changes=0",
            4000.0,
        )
        .unwrap();
        assert_eq!(
            (line.mass_g, line.state.as_str()),
            (None, "invalid:ill_conditioned")
        );
        let console = parse_line(
            "R t=1.000 mass=- u=- unit=g state=invalid:saturated final=0",
            4000.0,
        )
        .unwrap();
        assert_eq!(console.mass_g, None);
        assert_eq!(parse_line("config method=step n=5 D=24", 4000.0), None);
        assert_eq!(parse_line("t_s,mass_g,u_g,state,final", 4000.0), None);
        assert_eq!(
            parse_line("R t=x mass=1 unit=g state=stable final=0", 4000.0),
            None
        );
    }
}
