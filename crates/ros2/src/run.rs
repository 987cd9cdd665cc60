//! The bridge's process: the DDS domain of the configuration and the
//! environment, the daemon's state followed over shared memory (waiting
//! for a daemon that is not up yet, subscribing again to a restarted one),
//! each state published, and a summary at the end.

use crate::dds::Dds;
use crate::plan::{Plan, PlanOptions};
use sar_shm::{Client, ShmError, StateSubscription};
use std::time::{Duration, Instant};

/// The environment variable ROS 2 reads the domain from.
pub const ROS_DOMAIN_ID: &str = "ROS_DOMAIN_ID";
/// Without a state for this long, the bridge subscribes again (a restarted
/// daemon has new services).
pub const IDLE: Duration = Duration::from_secs(2);
/// How often the bridge looks for a daemon that does not run yet.
pub const RETRY: Duration = Duration::from_millis(500);

/// The domain: `[ros2] domain_id` or `ROS_DOMAIN_ID` (its value; empty: not
/// set), else 0. Both set to different domains is an error, never a
/// silent choice.
pub fn domain_id(configured: Option<u16>, env: Option<&str>) -> Result<u16, String> {
    let env = env.map(str::trim).filter(|v| !v.is_empty());
    let from_env = env
        .map(|v| {
            v.parse::<u16>()
                .ok()
                .filter(|d| *d <= sar_config::MAX_DOMAIN_ID)
                .ok_or_else(|| {
                    format!(
                        "{ROS_DOMAIN_ID}={v:?}: not a domain id (0..={})",
                        sar_config::MAX_DOMAIN_ID
                    )
                })
        })
        .transpose()?;
    match (configured, from_env) {
        (Some(c), Some(e)) if c != e => Err(format!(
            "[ros2] domain_id = {c} and {ROS_DOMAIN_ID}={e} disagree: remove one"
        )),
        (Some(d), _) | (None, Some(d)) => Ok(d),
        (None, None) => Ok(0),
    }
}

/// What a run did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Summary {
    /// States received.
    pub states: u64,
    /// States lost (gaps in the cycle numbers).
    pub states_lost: u64,
    /// Per topic: its name, messages written, messages DDS refused.
    pub topics: Vec<(&'static str, u64, u64)>,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "states {}, lost {}; written (refused):",
            self.states, self.states_lost
        )?;
        for (name, written, refused) in &self.topics {
            write!(f, " {name} {written} ({refused})")?;
        }
        Ok(())
    }
}

fn summary(plan: &Plan, dds: &Dds) -> Summary {
    let c = plan.counts();
    Summary {
        states: c.states,
        states_lost: c.states_lost,
        topics: dds
            .counts()
            .map(|(t, n)| (t.name(), n.written, n.refused))
            .collect(),
    }
}

/// Subscribes to the daemon's state, waiting (every [`RETRY`]) while no
/// daemon runs, until `stop()`. Other errors (no right to the runtime
/// directory, a damaged file) end it.
fn subscribe(
    client: &Client,
    prefix: &str,
    stop: &impl Fn() -> bool,
) -> Result<Option<StateSubscription>, String> {
    let mut said = false;
    while !stop() {
        match client.subscribe() {
            Ok(sub) => {
                if said {
                    eprintln!("sar-ros2: the daemon runs: bridging");
                }
                return Ok(Some(sub));
            }
            Err(e @ ShmError::NoDaemon { .. }) => {
                if !said {
                    eprintln!("sar-ros2: waiting for the daemon (prefix {prefix:?}): {e}");
                    said = true;
                }
                std::thread::sleep(RETRY);
            }
            Err(e) => return Err(e.to_string()),
        }
    }
    Ok(None)
}

/// Bridges the daemon under `prefix` to `dds` until `stop()`: every state
/// through `plan` onto DDS. Returns what it did.
pub fn bridge(
    prefix: &str,
    mut plan: Plan,
    mut dds: Dds,
    stop: impl Fn() -> bool,
) -> Result<Summary, String> {
    let client = Client::new(prefix).map_err(|e| e.to_string())?;
    let Some(mut sub) = subscribe(&client, prefix, &stop)? else {
        return Ok(summary(&plan, &dds));
    };
    let mut failure: Option<String> = None;
    let mut last = Instant::now();
    let mut waiting = false;
    while !stop() && failure.is_none() {
        let n = sub.wait(Duration::from_millis(100), |s| {
            plan.on_state(s, |topic, _stamp_ns, cdr| {
                if let Err(e) = dds.write(topic, cdr) {
                    failure.get_or_insert(e.to_string());
                }
            });
        });
        if n > 0 {
            last = Instant::now();
            if waiting {
                eprintln!("sar-ros2: the daemon publishes again");
                waiting = false;
            }
        } else if last.elapsed() > IDLE {
            if !waiting {
                eprintln!("sar-ros2: the daemon stopped publishing; waiting for it");
                waiting = true;
            }
            // A restarted daemon has new services: subscribe again.
            if let Ok(s) = client.subscribe() {
                sub = s;
                plan.restart();
            }
            last = Instant::now();
        }
    }
    match failure {
        Some(e) => Err(e),
        None => Ok(summary(&plan, &dds)),
    }
}

/// `sar-ros2` from its command line: the configuration (`None`: the
/// built-in one), the daemon's prefix; runs until SIGINT or SIGTERM.
pub fn run_cli(config: Option<&std::path::Path>, prefix: &str) -> Result<(), String> {
    let cfg = match config {
        Some(path) => sar_config::load(path),
        None => sar_config::builtin(),
    }
    .map_err(|e| e.to_string())?;
    let env = std::env::var(ROS_DOMAIN_ID).ok();
    let domain = domain_id(cfg.ros2.domain_id, env.as_deref())?;
    sar_loop::rt::install_stop_handler()
        .map_err(|e| format!("cannot install signal handlers: {e}"))?;
    let dds = Dds::new(domain, cfg.ros2.interfaces.as_deref()).map_err(|e| e.to_string())?;
    let interfaces = match &cfg.ros2.interfaces {
        Some(list) => list
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        None => "every interface".to_owned(),
    };
    eprintln!(
        "sar-ros2: daemon prefix {prefix:?} -> DDS domain {domain} ({interfaces}), {} topics, read-only",
        crate::topics::ALL.len()
    );
    let summary = bridge(
        prefix,
        Plan::new(PlanOptions::from_config(&cfg)),
        dds,
        sar_loop::rt::stop_requested,
    )?;
    eprintln!("sar-ros2: stopped: {summary}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_domain_comes_from_the_configuration_or_the_environment_never_both() {
        assert_eq!(domain_id(None, None), Ok(0));
        assert_eq!(domain_id(Some(7), None), Ok(7));
        assert_eq!(domain_id(None, Some("42")), Ok(42));
        assert_eq!(domain_id(None, Some(" ")), Ok(0));
        assert_eq!(domain_id(Some(3), Some("3")), Ok(3));
        let both = domain_id(Some(3), Some("4")).unwrap_err();
        assert!(both.contains("disagree"), "{both}");
        for bad in ["x", "-1", "233", "70000"] {
            let e = domain_id(None, Some(bad)).unwrap_err();
            assert!(e.contains(ROS_DOMAIN_ID), "{e}");
        }
    }
}
