//! Prints, or with `--write` writes, what the keys' declaration
//! (`crates/config/src/keys`) says about the configuration: the built-in
//! configuration (`crates/config/src/default_config.toml`) and the README's
//! table of every key (between its two marker lines). `crates/config/tests/keys.rs`
//! fails while either file differs.
//!
//! ```sh
//! cargo run -p sar-config --example config_docs -- --write
//! ```

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_config::docs;
use std::path::Path;

fn main() {
    let toml = docs::default_toml();
    if !std::env::args().any(|a| a == "--write") {
        print!("{toml}");
        println!();
        print!("{}", docs::readme_table());
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let toml_path = root.join("crates/config/src/default_config.toml");
    std::fs::write(&toml_path, &toml).expect("default_config.toml");
    let readme_path = root.join("README.md");
    let readme = std::fs::read_to_string(&readme_path).expect("README.md");
    let (before, rest) = readme
        .split_once(docs::README_BEGIN)
        .expect("the README's marker before the keys");
    let (_, after) = rest
        .split_once(docs::README_END)
        .expect("the README's marker after the keys");
    let readme = format!(
        "{before}{}\n{}{}{after}",
        docs::README_BEGIN,
        docs::readme_table(),
        docs::README_END
    );
    std::fs::write(&readme_path, readme).expect("README.md");
    println!(
        "wrote {} and {}",
        toml_path.display(),
        readme_path.display()
    );
}
