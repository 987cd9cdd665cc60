//! Regenerates the identification fixtures (`tests/fixtures/identify/*.mcap`)
//! from the simulator's scenarios: `cargo run -p sar-tests --example
//! make_identify_fixtures`. See `tests/identify_fixtures.rs`.
#![allow(clippy::unwrap_used, clippy::panic, clippy::indexing_slicing)]

fn main() {
    let dir = sar_tests::identify_fixtures::dir();
    std::fs::create_dir_all(&dir).unwrap();
    for f in sar_tests::identify_fixtures::all() {
        let path = sar_tests::identify_fixtures::write(&f, &dir);
        let size = std::fs::metadata(&path).unwrap().len();
        println!("{} ({size} bytes)", path.display());
    }
}
