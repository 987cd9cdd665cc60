//! Criterion benchmarks of the estimator (filled when the modules land).
fn main() {}
