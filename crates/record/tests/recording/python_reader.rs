//! An independent reader: Python's `mcap` and `mcap-ros2-support` decode every
//! channel of a recording (and of a recovered one) with the ROS 2 decoder, from
//! the schemas the file carries, and every field must equal what was recorded,
//! bit for bit. The packages are installed on first use under
//! `target/test-readers/` (`scripts/setup-test-readers.sh`); fails when
//! python3 or its pip is missing, ignored when built with `SAR_SKIP_PYTHON=1`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_msgs::msgs::*;
use sar_record::*;
use std::fmt::Write as _;
use std::path::Path;

/// Runs the script with the packages `scripts/setup-test-readers.sh`
/// installs (on first use) under `target/test-readers/py`.
fn python_read(file: &Path) -> Option<String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_recording.py");
    let out = sar_test_support::process::run_ok(
        crate::readers::python().arg(&script).arg(file),
        "the Python reader failed ()",
    );
    Some(String::from_utf8(out.stdout).unwrap())
}

/// One message's canonical line, as the script prints it.
#[derive(Default)]
struct Line(Vec<String>);

impl Line {
    fn f(&mut self, k: &str, v: f64) -> &mut Self {
        self.0.push(format!("{k}=f:{}", v.to_bits()));
        self
    }
    fn fa(&mut self, k: &str, v: &[f64]) -> &mut Self {
        for (i, x) in v.iter().enumerate() {
            self.f(&format!("{k}[{i}]"), *x);
        }
        self
    }
    fn i(&mut self, k: &str, v: impl std::fmt::Display) -> &mut Self {
        self.0.push(format!("{k}=i:{v}"));
        self
    }
    fn b(&mut self, k: &str, v: bool) -> &mut Self {
        self.0.push(format!("{k}=b:{}", u8::from(v)));
        self
    }
    fn s(&mut self, k: &str, v: &str) -> &mut Self {
        let mut hex = String::new();
        for b in v.as_bytes() {
            write!(hex, "{b:02x}").unwrap();
        }
        self.0.push(format!("{k}=s:{hex}"));
        self
    }
    fn header(&mut self, stamp_ns: u64, frame: &str) -> &mut Self {
        self.i("header.stamp.sec", stamp_ns / 1_000_000_000)
            .i("header.stamp.nanosec", stamp_ns % 1_000_000_000)
            .s("header.frame_id", frame)
    }
    fn joints(&mut self, stamp_ns: u64, names: &[&str], pos: &[f64]) -> &mut Self {
        self.header(stamp_ns, "");
        for (i, n) in names.iter().enumerate() {
            self.s(&format!("name[{i}]"), n);
        }
        self.fa("position", pos)
    }
}

fn fields(m: &Outgoing) -> String {
    let mut l = Line::default();
    match m {
        Outgoing::SensorWrench(w)
        | Outgoing::TipWrench(w)
        | Outgoing::TipWrenchFiltered(w)
        | Outgoing::SimTruth(w) => {
            l.header(w.stamp_ns, w.frame_id.as_str())
                .f("wrench.force.x", w.force_n[0])
                .f("wrench.force.y", w.force_n[1])
                .f("wrench.force.z", w.force_n[2])
                .f("wrench.torque.x", w.torque_nm[0])
                .f("wrench.torque.y", w.torque_nm[1])
                .f("wrench.torque.z", w.torque_nm[2]);
        }
        Outgoing::Joints(j) => {
            l.joints(j.stamp_ns, &ActiveJointState::NAMES, &j.q_m);
        }
        Outgoing::PassiveJoints(j) => {
            l.joints(j.stamp_ns, &PassiveJointState::NAMES, &j.q_rad);
        }
        Outgoing::EstimatorState(s) => {
            l.header(s.stamp_ns, "base")
                .i("cycle", s.cycle)
                .i("now_ns", s.now_ns)
                .i("sensor_stamp_ns", s.sensor_stamp_ns)
                .i("joints_stamp_ns", s.joints_stamp_ns)
                .i("sensor_age_ns", s.sensor_age_ns)
                .i("joints_age_ns", s.joints_age_ns)
                .i("tip_outcome", s.tip_outcome.code())
                .fa("ujoint_m", &s.ujoint_m)
                .fa("tip_m", &s.tip_m)
                .f("support_distance_m", s.support_distance_m)
                .fa("ujoint_force_n", &s.ujoint_force_n)
                .fa("tip_force_n", &s.tip_force_n)
                .fa("tip_force_std_n", &s.tip_force_std_n)
                .f("axial_n", s.axial_n)
                .f("lateral_n", s.lateral_n)
                .f("torsion_nm", s.torsion_nm)
                .fa("tip_force_filtered_n", &s.tip_force_filtered_n)
                .i("guard_state", s.guard_state.code())
                .i("guard_reason_code", s.guard_reason_code)
                .s("guard_reason_text", s.guard_reason_text.as_str())
                .i("flags", s.flags);
        }
        Outgoing::GuardEvent(g) => {
            l.header(g.stamp_ns, "base")
                .i("cycle", g.cycle)
                .i("from_state", g.from_state.code())
                .i("to_state", g.to_state.code())
                .i("reason_code", g.reason_code)
                .s("reason_text", g.reason_text.as_str());
        }
        Outgoing::CycleInput(c) => {
            l.header(c.stamp_ns, "base")
                .i("cycle", c.cycle)
                .i("now_ns", c.now_ns)
                .i("clock_status", c.clock_status.code())
                .fa("sensor_force_n", &c.sensor_force_n)
                .fa("sensor_torque_nm", &c.sensor_torque_nm)
                .i("sensor_counter", c.sensor_counter)
                .i("sensor_status", c.sensor_status)
                .i("sensor_stamp_ns", c.sensor_stamp_ns)
                .b("sensor_valid", c.sensor_valid)
                .fa("joints_q_m", &c.joints_q_m)
                .i("joints_stamp_ns", c.joints_stamp_ns)
                .b("joints_valid", c.joints_valid)
                .i("drive_state", c.drive_state.code())
                .i("drive_fault_axis", c.drive_fault_axis)
                .i("drive_fault_code", c.drive_fault_code)
                .fa("target_q_m", &c.target_q_m)
                .b("target_valid", c.target_valid)
                .i("command_kind", c.command_kind.code())
                .fa("command_values", &c.command_values)
                .i("command_arg", c.command_arg)
                .fa("move_tip_m", &c.move_tip_m)
                .fa("limits_n", &c.limits_n)
                .i("drive_action", c.drive_action.code())
                .fa("setpoint_q_m", &c.setpoint_q_m)
                .i("reply_status", c.reply_status)
                .i("reply_reason", c.reply_reason)
                .fa("limits_in_use_n", &c.limits_in_use_n)
                .i("publisher_idle_ns", c.publisher_idle_ns)
                .f("back_out_m", c.back_out_m)
                .f("move_max_force_n", c.move_max_force_n)
                .b("sensor_drained_counted", c.sensor_drained_counted)
                .i("sensor_drained_samples", c.sensor_drained_samples)
                .i("sensor_drained_jumps", c.sensor_drained_jumps)
                .i("command_layout", c.command_layout.code())
                .f("hold_max_force_n", c.hold_max_force_n)
                .f("push_axial_n", c.push_axial_n)
                .fa("excite_amplitude_m", &c.excite_amplitude_m)
                .fa("excite_freq_hz", &c.excite_freq_hz)
                .f("excite_duration_s", c.excite_duration_s)
                .f("excite_fade_s", c.excite_fade_s);
        }
        Outgoing::RecorderDrops(d) => {
            l.header(d.stamp_ns, "")
                .i("dropped", d.dropped)
                .i("written", d.written)
                .i("queue_capacity", d.queue_capacity);
        }
        // Chunks live only in the recorder's queue (the file holds the
        // joined `/sar/cycle/snapshot`, which `strict_readers` decodes).
        Outgoing::SnapshotChunk(c) => panic!("a snapshot chunk is never read back: {c:?}"),
    }
    l.0.join(";")
}

/// What the script must print for these messages (in file order).
fn expected(msgs: &[Outgoing]) -> String {
    let mut out = String::from("profile ros2\n");
    for t in Topic::FULL {
        writeln!(out, "channel {} {} ros2msg cdr", t.name(), t.type_name()).unwrap();
    }
    let mut seq = std::collections::BTreeMap::<&str, u32>::new();
    let mut lines: Vec<(&str, u32, String)> = msgs
        .iter()
        .map(|m| {
            let topic = m.topic().name();
            let s = seq.entry(topic).or_default();
            let line = format!("msg {topic}|{s}|{t}|{t}|{}", fields(m), t = m.stamp_ns());
            *s += 1;
            (topic, *s - 1, line)
        })
        .collect();
    lines.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
    for (_, _, l) in lines {
        out.push_str(&l);
        out.push('\n');
    }
    out
}

fn compare(got: &str, want: &str) {
    for (i, (g, w)) in got.lines().zip(want.lines()).enumerate() {
        assert_eq!(g, w, "line {i}");
    }
    assert_eq!(got.lines().count(), want.lines().count());
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
fn python_decodes_every_channel_bit_for_bit() {
    let dir = sar_test_support::scratch!("python");
    let mut files = FileOptions::new(&dir, "rec");
    files.chunk_size_bytes = 32 * 1024;
    let mut config = RecorderConfig::new(files);
    config.status_interval_ns = 20_000_000;
    let mut rec = Recorder::start(config).unwrap();
    for k in 0..400 {
        for m in sar_test_support::messages::cycle_messages(k) {
            assert!(rec.push(m));
        }
    }
    let report = rec.stop().unwrap();
    let bytes = read_file(&report.files[0]).unwrap();
    // What the file holds, by our reader, with the recorder's own status
    // messages; the test above checks these equal what was pushed.
    let mut reader = McapReader::new(&bytes).unwrap();
    let raw: Vec<RawMessage> = reader.by_ref().map(|m| m.unwrap()).collect();
    let msgs: Vec<Outgoing> = raw
        .iter()
        .map(|m| {
            let topic = Topic::from_name(&reader.channels()[&m.channel_id].topic).unwrap();
            Outgoing::decode(topic, &m.data).unwrap()
        })
        .collect();
    assert!(msgs.iter().any(|m| m.topic() == Topic::GuardEvents));
    assert!(msgs.iter().any(|m| m.topic() == Topic::RecorderDrops));
    let Some(got) = python_read(&report.files[0]) else {
        return;
    };
    compare(&got, &expected(&msgs));

    // A recovered file reads too (cut inside its last chunk).
    let cut = dir.join("cut.mcap");
    let fixed = dir.join("fixed.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let r = recover(&cut, &fixed).unwrap();
    assert!(r.messages > 0);
    let got = python_read(&fixed).unwrap();
    let n = r.messages as usize;
    compare(&got, &expected(&msgs[..n]));
}
