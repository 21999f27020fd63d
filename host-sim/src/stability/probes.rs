//! The methods the map probes: each in f64 and in f32, the f32 one knowing its f64 twin so
//! the two are judged on the same runs. The map's own specs must parse; a typo is a bug here,
//! never a cell.

use super::conditions::ORDER_MAP_DECIMATION;
use crate::method::Method;
use crate::montecarlo::Precision;

/// One method in the map.
#[derive(Clone, Debug)]
pub struct Probe {
    /// The panel or row it belongs to (e.g. `step D=16`, `model bank`).
    pub family: String,
    /// The method.
    pub method: Method,
    /// Its order, where one applies (slice A's x axis).
    pub order: Option<usize>,
    /// For an f32 probe, the index of the same method in f64.
    pub twin: Option<usize>,
}

fn parse(spec: &str) -> Method {
    spec.parse()
        .unwrap_or_else(|e| panic!("the map's own spec `{spec}` parses: {e}"))
}

fn in_f32(spec: &str) -> String {
    if spec.contains(':') {
        format!("{spec},precision=f32")
    } else {
        format!("{spec}:precision=f32")
    }
}

/// Push `spec` in f64 and in f32 (the f32 one knowing its twin).
pub(super) fn push_pair(probes: &mut Vec<Probe>, family: &str, spec: &str, order: Option<usize>) {
    let twin = probes.len();
    probes.push(Probe {
        family: family.to_string(),
        method: parse(spec),
        order,
        twin: None,
    });
    probes.push(Probe {
        family: family.to_string(),
        method: parse(&in_f32(spec)),
        order,
        twin: Some(twin),
    });
}

/// Slice A's probes: every family where an order applies, at every order, f64 and f32.
pub fn order_probes(orders: &[usize]) -> Vec<Probe> {
    let d = ORDER_MAP_DECIMATION;
    let families: [(String, String); 5] = [
        (format!("step D={d}"), format!("step:D={d}")),
        ("step D=1".into(), "step:D=1".into()),
        (format!("covariance D={d}"), format!("covariance:D={d}")),
        (format!("iv D={d}"), format!("iv:D={d}")),
        (format!("bc D={d}"), format!("bc:D={d}")),
    ];
    let mut probes = Vec::new();
    for (family, base) in &families {
        for &order in orders {
            push_pair(
                &mut probes,
                family,
                &format!("{base},n={order}"),
                Some(order),
            );
        }
    }
    probes
}

/// The firmware's default method (`firmware/weighing.toml`, test
/// `the_firmware_default_is_the_shipped_method`): its row label and spec.
const FIRMWARE_DEFAULT: (&str, &str) = ("step n=5 D=24 (firmware default)", "step:n=5,D=24");

/// Slices B and C: every method at its default configuration (the speed study's), f64 and
/// f32.
pub fn default_probes() -> Vec<Probe> {
    let mut probes = Vec::new();
    for (family, spec) in [
        (FIRMWARE_DEFAULT.0, FIRMWARE_DEFAULT.1),
        ("step n=7 D=1 (thesis)", "step:n=7,D=1"),
        ("covariance n=7 D=16", "covariance:n=7,D=16"),
        ("iv n=7 D=16", "iv:n=7,D=16"),
        ("bc n=7 D=16", "bc:n=7,D=16"),
        ("ramp n=5 D=16", "ramp:n=5,D=16"),
        ("model bank (K=33, ±30%)", "model"),
        ("model at calibration (K=1)", "model:K=1,span=0.5-2"),
        ("settled average", "settled"),
        ("moving average", "moving"),
    ] {
        push_pair(&mut probes, family, spec, None);
    }
    probes
}

/// `f32` or `f64`, as the CSV and the labels name a method's precision.
pub(super) fn precision_name(method: &Method) -> &'static str {
    match method.precision() {
        Precision::F32 => "f32",
        Precision::F64 => "f64",
    }
}

/// A probe's row label: its family and precision.
pub(super) fn probe_label(probe: &Probe) -> String {
    format!(
        "{} {}",
        probe.family,
        if probe.method.precision() == Precision::F32 {
            "f32"
        } else {
            "f64"
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slice_a_has_every_family_at_every_order_in_both_precisions() {
        let probes = order_probes(&[3, 7]);
        assert_eq!(probes.len(), 5 * 2 * 2);
        // Family by family, order by order, f64 then its f32 twin.
        assert_eq!(probes[0].family, "step D=16");
        assert_eq!(probes[0].method.to_string(), "step:n=3,D=16");
        assert_eq!(probes[0].order, Some(3));
        assert_eq!(probes[1].method.precision(), Precision::F32);
        assert_eq!(probes[1].twin, Some(0));
        assert_eq!(probes[2].order, Some(7));
        assert_eq!(probes[19].family, "bc D=16");
        for (p, probe) in probes.iter().enumerate() {
            match probe.twin {
                Some(twin) => {
                    assert_eq!(twin + 1, p);
                    assert_eq!(probes[twin].family, probe.family);
                    assert_eq!(probes[twin].method.precision(), Precision::F64);
                }
                None => assert_eq!(probe.method.precision(), Precision::F64),
            }
        }
    }

    #[test]
    fn every_default_method_is_probed_in_both_precisions() {
        let probes = default_probes();
        assert_eq!(probes.len(), 20);
        assert_eq!(
            probe_label(&probes[0]),
            "step n=5 D=24 (firmware default) f64"
        );
        assert_eq!(
            probe_label(&probes[1]),
            "step n=5 D=24 (firmware default) f32"
        );
        assert_eq!(precision_name(&probes[13].method), "f32");
        assert_eq!(in_f32("model"), "model:precision=f32");
        assert_eq!(in_f32("step:n=7"), "step:n=7,precision=f32");
    }

    /// The map's "firmware default" row is the method the firmware ships with.
    #[test]
    fn the_firmware_default_is_the_shipped_method() {
        let (shipped, _) = crate::study::firmware_default().unwrap();
        let probed = parse(&in_f32(FIRMWARE_DEFAULT.1));
        assert_eq!(probed.to_string(), shipped.to_string());
    }
}
