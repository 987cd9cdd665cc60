//! `ros2/sar_msgs`, the `.msg` files as a ROS 2 interface package: its
//! `msg/` is the project's one definition of each message (the files the
//! recordings embed and `crates/msgs/tests/layout.rs` checks the encoders
//! against: the same files, byte for byte), its `CMakeLists.txt` hands every
//! one of them to `rosidl_generate_interfaces` with its dependencies, its
//! `package.xml` makes it an interface package; and ROS 2 Jazzy's own
//! `rosidl_adapter` turns each into IDL that `rosidl_parser` reads (the
//! first step of `rosidl_generate_interfaces`), with the fields of the
//! `.msg` file, under the names whose DDS types the bridge publishes.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::{prefix_site_packages, readers, repo_root};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn package() -> PathBuf {
    repo_root().join("ros2/sar_msgs")
}

/// The `.msg` files of a directory: name -> bytes.
fn msg_files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "msg"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

/// A `.msg` file's field names, in order (constants and comments left out).
fn field_names(text: &str) -> Vec<String> {
    text.lines()
        .map(|l| l.split('#').next().unwrap().trim())
        .filter(|l| !l.is_empty())
        .filter_map(|l| {
            let mut parts = l.split_whitespace();
            let (_ty, rest) = (parts.next()?, parts.next()?);
            (!rest.contains('=') && !l.contains('=')).then(|| rest.to_owned())
        })
        .collect()
}

#[test]
fn the_package_is_the_msg_files_and_hands_each_to_rosidl() {
    let ours = msg_files(&repo_root().join("crates/msgs/msg"));
    let pkg = msg_files(&package().join("msg"));
    assert!(ours.len() >= 7, "{:?}", ours.keys());
    assert_eq!(pkg, ours, "ros2/sar_msgs/msg is not crates/msgs/msg");
    // One definition: a link to the directory, not a copy that could drift.
    let link = std::fs::symlink_metadata(package().join("msg")).unwrap();
    assert!(link.file_type().is_symlink(), "ros2/sar_msgs/msg is a copy");
    assert_eq!(
        package().join("msg").canonicalize().unwrap(),
        repo_root().join("crates/msgs/msg").canonicalize().unwrap()
    );
    let cmake = std::fs::read_to_string(package().join("CMakeLists.txt")).unwrap();
    let call = cmake
        .split("rosidl_generate_interfaces(${PROJECT_NAME}")
        .nth(1)
        .and_then(|r| r.split(')').next())
        .expect("rosidl_generate_interfaces(${PROJECT_NAME} ...)");
    let listed: Vec<String> = call
        .split_whitespace()
        .filter_map(|w| w.trim_matches('"').strip_prefix("msg/").map(str::to_owned))
        .collect();
    assert_eq!(listed, ours.keys().cloned().collect::<Vec<_>>(), "{call}");
    assert!(
        call.contains("DEPENDENCIES std_msgs builtin_interfaces"),
        "{call}"
    );
    assert!(cmake.contains("project(sar_msgs)"));
    let xml = std::fs::read_to_string(package().join("package.xml")).unwrap();
    for needed in [
        "<name>sar_msgs</name>",
        "<member_of_group>rosidl_interface_packages</member_of_group>",
        "<buildtool_depend>rosidl_default_generators</buildtool_depend>",
        "<exec_depend>rosidl_default_runtime</exec_depend>",
        "<depend>std_msgs</depend>",
        "<depend>builtin_interfaces</depend>",
        "<build_type>ament_cmake</build_type>",
    ] {
        assert!(xml.contains(needed), "package.xml lacks {needed}");
    }
}

/// ROS 2 Jazzy's `.msg` -> IDL step, then its IDL parser, on every file:
/// `{file: [package, "msg", type, [members]]}`.
const ROSIDL: &str = r#"
import json, pathlib, sys, tempfile
from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_parser.parser import parse_idl_file
from rosidl_parser.definition import IdlLocator, Message
pkg = pathlib.Path(sys.argv[1])
out = {}
with tempfile.TemporaryDirectory() as tmp:
    for f in sorted((pkg / "msg").glob("*.msg")):
        idl = convert_msg_to_idl(pkg, "sar_msgs", pathlib.Path("msg") / f.name, pathlib.Path(tmp))
        parsed = parse_idl_file(IdlLocator(pathlib.Path(tmp), pathlib.Path(idl).relative_to(tmp)))
        for m in parsed.content.get_elements_of_type(Message):
            out[f.name] = list(m.structure.namespaced_type.namespaced_name()) + [
                [member.name for member in m.structure.members]]
print(json.dumps(out))
"#;

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1: no Python rosidl")]
fn rosidl_of_ros2_jazzy_turns_every_msg_file_into_idl() {
    let site = prefix_site_packages(&readers().join("rosidl"));
    let out = Command::new("python3")
        .args(["-c", ROSIDL])
        .arg(package())
        .env("PYTHONPATH", &site)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("PYTHONNOUSERSITE", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rosidl: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    let parsed: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let files = msg_files(&package().join("msg"));
    for (name, bytes) in &files {
        let m = &parsed[name];
        let ty = name.trim_end_matches(".msg");
        assert_eq!(m[0], "sar_msgs", "{name}: {m}");
        assert_eq!(m[1], "msg", "{name}: {m}");
        assert_eq!(m[2], ty, "{name}: {m}");
        let members: Vec<String> = m[3]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap().to_owned())
            .collect();
        assert_eq!(
            members,
            field_names(&String::from_utf8_lossy(bytes)),
            "{name}"
        );
    }
    // The sar_msgs types the bridge publishes are rosidl's, on DDS as
    // ROS 2's type support names them.
    for topic in sar_ros2::topics::ALL {
        let ty = topic.type_name();
        if let Some(name) = ty.strip_prefix("sar_msgs/msg/") {
            assert!(files.contains_key(&format!("{name}.msg")), "{ty}");
            assert_eq!(
                sar_ros2::names::dds_type(ty).unwrap(),
                format!("sar_msgs::msg::dds_::{name}_")
            );
        }
    }
}
