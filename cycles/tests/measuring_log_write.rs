//! Measuring logs are written whole or not at all, and never through a symlink.

use probebridge_cycles::measuring_log::write;

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("pb-mlog-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_symlink_at_the_log_path_is_refused_and_its_target_kept() {
    let d = tmp("symlink");
    let target = d.join("precious.txt");
    std::fs::write(&target, "keep").unwrap();
    std::os::unix::fs::symlink(&target, d.join("TCHPR431.TXT")).unwrap();
    let e = write(&d, "TCHPR431.TXT", "new protocol").unwrap_err();
    assert!(e.to_string().contains("TCHPR431.TXT"), "{e}");
    assert!(e.to_string().contains("symbolic link"), "{e}");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "keep");
}

#[test]
fn a_log_replaces_the_previous_one_whole_and_leaves_no_temporary() {
    let d = tmp("replace");
    write(&d, "TCHPRAUTO.html", "first").unwrap();
    let p = write(&d, "TCHPRAUTO.html", "second").unwrap();
    assert_eq!(std::fs::read_to_string(p).unwrap(), "second");
    let names: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["TCHPRAUTO.html"], "{names:?}");
}
