//! Where the examples write their figures and the main job (`examples/papers.rs`) its report:
//! the README's `target/figures/papers.md`, in cargo's target directory.

use crate::common;
use std::path::{Path, PathBuf};

/// Without `CARGO_TARGET_DIR`, the workspace root's `target/` (this package, `estim`, is the
/// workspace root), and the README names that path. Before, it was the reproductions
/// library's own folder: `examples/reproductions/target/figures/papers.md`.
#[test]
fn figures_go_to_the_workspace_target_dir_named_in_the_readme() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    assert!(
        manifest.contains("[workspace]"),
        "{} is not the workspace root",
        root.display()
    );
    let report = common::target_dir(None, None)
        .join("figures")
        .join("papers.md");
    let relative = report.strip_prefix(root).unwrap_or_else(|_| {
        panic!(
            "{} is outside the workspace root {}",
            report.display(),
            root.display()
        )
    });
    assert_eq!(relative, Path::new("target/figures/papers.md"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(
        readme.contains("`target/figures/papers.md`"),
        "the README does not name target/figures/papers.md"
    );
}

/// `$CARGO_TARGET_DIR` at run time wins over its value when the example was built, which wins
/// over the workspace's `target/`.
#[test]
fn cargo_target_dir_overrides_the_default() {
    let (run, built) = (PathBuf::from("/tmp/run"), PathBuf::from("/tmp/built"));
    assert_eq!(
        common::target_dir(Some(run.clone()), Some(built.clone())),
        run
    );
    assert_eq!(common::target_dir(None, Some(built.clone())), built);
}
