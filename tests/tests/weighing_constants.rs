//! The committed firmware constants are what host-sim's reader makes of `weighing.toml`.

use tests::weighing_constants::{shipped, workspace_root, SHIPPED_CONSTANTS, UPDATE_VAR};

#[test]
fn firmware_constants_match_the_shipped_weighing_toml() {
    let expected = shipped().expect("firmware/weighing.toml is a valid weighing configuration");
    let path = workspace_root().join(SHIPPED_CONSTANTS);
    if std::env::var_os(UPDATE_VAR).is_some() {
        std::fs::write(&path, &expected).expect("write the constants");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == expected,
        "{SHIPPED_CONSTANTS} is not what firmware/weighing.toml gives: after changing the TOML, \
         run `{UPDATE_VAR}=1 cargo test -p tests --test weighing_constants` and commit the file"
    );
}
