//! Test configuration from the environment: `SAR_SKIP_PYTHON=1` marks the
//! test that needs Python's Cyclone DDS (`scripts/setup-test-readers.sh`)
//! as ignored, as the other strict readers' tests are, so that a run
//! without Python shows it as ignored, never as passed. Nothing else is
//! configured.

fn main() {
    println!("cargo::rerun-if-env-changed=SAR_SKIP_PYTHON");
    println!("cargo::rustc-check-cfg=cfg(sar_skip_python)");
    if std::env::var("SAR_SKIP_PYTHON").is_ok_and(|v| v == "1") {
        println!("cargo::rustc-cfg=sar_skip_python");
    }
}
