//! Test configuration from the environment: `SAR_SKIP_PYTHON=1` and
//! `SAR_SKIP_NODE=1` mark the tests that need the strict readers (Python,
//! Node; `scripts/setup-test-readers.sh`) as ignored, so that a run without
//! them shows them as ignored, never as passed; `SAR_SKIP_ROOT_TESTS=1` does
//! the same for the tests of the access model, which run processes as other
//! users (root only). Nothing else is configured.

fn main() {
    for (var, cfg) in [
        ("SAR_SKIP_PYTHON", "sar_skip_python"),
        ("SAR_SKIP_NODE", "sar_skip_node"),
        ("SAR_SKIP_ROOT_TESTS", "sar_skip_root_tests"),
    ] {
        println!("cargo::rerun-if-env-changed={var}");
        println!("cargo::rustc-check-cfg=cfg({cfg})");
        if std::env::var(var).is_ok_and(|v| v == "1") {
            println!("cargo::rustc-cfg={cfg}");
        }
    }
}
