//! Every machine shipped in configs/machines parses and validates.

#[test]
fn shipped_machines_are_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/machines");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        // `<machine>.presets.toml` beside a machine is its preset table (the cycles').
        let presets = p.to_string_lossy().ends_with(".presets.toml");
        if p.extension().is_some_and(|x| x == "toml") && !presets {
            probebridge_hal::config::MachineConfig::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 2, "expected table-ac and head-b-table-c in {dir:?}");
}
