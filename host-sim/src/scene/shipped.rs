//! The shipped scenes, built into the binary: a `host-sim` copied anywhere still knows
//! `reference-step` and the rest by name. A scene added to `host-sim/scenes` must be added
//! here too; the test below fails until it is.

/// Every shipped scene: its name (the file stem) and the file's text, in name order.
pub const SHIPPED_SCENES: &[(&str, &str)] = &[
    (
        "calibration-drop",
        include_str!("../../scenes/calibration-drop.toml"),
    ),
    (
        "conveyor-ramp",
        include_str!("../../scenes/conveyor-ramp.toml"),
    ),
    (
        "drop-and-remove",
        include_str!("../../scenes/drop-and-remove.toml"),
    ),
    (
        "dropped-from-height",
        include_str!("../../scenes/dropped-from-height.toml"),
    ),
    (
        "off-calibration",
        include_str!("../../scenes/off-calibration.toml"),
    ),
    (
        "placed-by-hand",
        include_str!("../../scenes/placed-by-hand.toml"),
    ),
    (
        "quick-succession",
        include_str!("../../scenes/quick-succession.toml"),
    ),
    (
        "reference-step",
        include_str!("../../scenes/reference-step.toml"),
    ),
    ("rig-noise", include_str!("../../scenes/rig-noise.toml")),
    ("small-cell", include_str!("../../scenes/small-cell.toml")),
    ("two-items", include_str!("../../scenes/two-items.toml")),
    ("vibration", include_str!("../../scenes/vibration.toml")),
];

/// The text of the shipped scene `name`, if there is one.
pub fn shipped_scene(name: &str) -> Option<&'static str> {
    SHIPPED_SCENES
        .iter()
        .find(|(shipped, _)| *shipped == name)
        .map(|(_, text)| *text)
}

/// The names of the shipped scenes, for messages.
pub fn shipped_names() -> Vec<&'static str> {
    SHIPPED_SCENES.iter().map(|(name, _)| *name).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_holds_every_file_in_the_scenes_folder_as_it_is() {
        let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let mut on_disk: Vec<(String, String)> = std::fs::read_dir(&folder)
            .unwrap()
            .map(|entry| entry.unwrap().path())
            .filter(|path| path.extension().is_some_and(|ext| ext == "toml"))
            .map(|path| {
                let name = path.file_stem().unwrap().to_string_lossy().into_owned();
                (name, std::fs::read_to_string(&path).unwrap())
            })
            .collect();
        on_disk.sort();
        let built_in: Vec<(String, String)> = SHIPPED_SCENES
            .iter()
            .map(|(name, text)| (name.to_string(), text.to_string()))
            .collect();
        assert_eq!(
            built_in.iter().map(|(name, _)| name).collect::<Vec<_>>(),
            on_disk.iter().map(|(name, _)| name).collect::<Vec<_>>(),
            "host-sim/scenes and the built-in table differ"
        );
        assert_eq!(built_in, on_disk);
    }
}
