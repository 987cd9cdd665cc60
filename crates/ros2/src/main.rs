//! `sar-ros2`: the daemon's state on a ROS 2 network (see the crate's
//! documentation). One line on failure, exit status 1.

use clap::Parser;
use std::path::PathBuf;

/// The SAR robot's topics on a ROS 2 network (DDS), read-only.
#[derive(Debug, Parser)]
#[command(name = "sar-ros2", version)]
struct Args {
    /// The robot's configuration: its geometry for the 3D scene, the
    /// `[ros2]` section (domain, interfaces, rates). Default: the built-in
    /// configuration of `sard --sim`.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The daemon's service prefix.
    #[arg(long, env = "SAR_SERVICE_PREFIX", default_value = sar_shm::DEFAULT_PREFIX)]
    prefix: String,
}

fn main() {
    let args = Args::parse();
    if let Err(e) = sar_ros2::run::run_cli(args.config.as_deref(), &args.prefix) {
        eprintln!("sar-ros2: {e}");
        std::process::exit(1);
    }
}
