//! `chassis control --all estop`: the operator's e-stop on every robot served on this computer,
//! asked of all of them at once, each answer listed.
//!
//! A robot counts as stopped only when its chassisd answered the request with success (the
//! lock is then held, and written to its lock file, before the answer). No answer within the
//! bound, a refusal, a mirror that could not reach the robot, a robot that cannot be opened: the
//! robot is named NOT stopped, and the command exits non-zero. A robot whose thread is still
//! waiting when the bound is over is named NOT stopped too, never left out.
//!
//! A mirrored robot that did not answer may have its e-stop *pending*: its mirror
//! (`chassis-zenoh`) keeps the request asked and delivers it when the link returns. The robot is
//! still NOT stopped — nothing says it stands now — and is named so, marked pending. Pending is
//! what the robot's mux shows here ([`super::estop_pending`]), never what an answer's text says.

use std::sync::mpsc;
use std::time::Duration;

use chassis_client::{ControlKind, ControlRequest, ControlStatus, Robot, deadline, now_ns};

/// How long a robot that was not stopped is watched for its mirror's pending mark, which the
/// mirror publishes as it forwards the request (before any answer).
const PENDING_LOOK: Duration = Duration::from_millis(200);
/// What a pending robot's line says.
const PENDING: &str =
    "pending: the mirror keeps the e-stop asked and delivers it when the link returns";
use clap::Args;
use serde::Serialize;

#[derive(Debug, Clone, Args)]
pub struct EstopArgs {
    /// With --all: how long each robot may take to answer, ms.
    #[arg(long, default_value_t = 2000, global = true)]
    pub timeout_ms: u64,
}

/// One robot's answer to the fleet-wide e-stop.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct Answer {
    pub name: String,
    pub stopped: bool,
    /// Not stopped, but the robot's mirror keeps the e-stop asked and delivers it when the
    /// robot answers again.
    pub pending: bool,
    /// chassisd's message, or why there is no stop.
    pub message: String,
    pub answer_ms: Option<u64>,
}

fn ask(name: &str, timeout: Duration) -> Answer {
    let start = now_ns();
    let answered = |stopped: bool, pending: bool, message: String| Answer {
        name: name.to_string(),
        stopped,
        pending,
        message,
        answer_ms: Some(now_ns().saturating_sub(start) / 1_000_000),
    };
    let mut robot = match Robot::connect(name) {
        Ok(robot) => robot,
        Err(e) => return answered(false, false, format!("cannot reach it: {e}")),
    };
    let request = ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop");
    let why = match robot.control(request, timeout) {
        Ok(response) if response.is_ok() => {
            return answered(true, false, response.message().to_string());
        }
        Ok(response) => format!(
            "{}: {}",
            ControlStatus::name(response.status),
            response.message()
        ),
        Err(e) => e.to_string(),
    };
    let pending = kept_pending(&mut robot);
    answered(false, pending, why)
}

/// Whether the robot's mux shows its e-stop pending (a mirror keeps it asked), looking for at
/// most [`PENDING_LOOK`].
fn kept_pending(robot: &mut Robot) -> bool {
    let end = deadline(PENDING_LOOK);
    loop {
        match robot.latest_mux() {
            Ok(Some(m)) if super::estop_pending(&m) => return true,
            Ok(_) => {}
            Err(_) => return false,
        }
        let left = end.saturating_sub(now_ns());
        if left == 0 {
            return false;
        }
        if robot.wait_mux(Duration::from_nanos(left)).is_err() {
            return false;
        }
    }
}

/// Asks every robot in `names` for the e-stop at once; one answer per robot, in `names`' order,
/// within `timeout` plus a margin for the threads themselves.
pub fn estop_robots(names: &[String], timeout: Duration) -> Vec<Answer> {
    let (tx, rx) = mpsc::channel::<Answer>();
    let mut answers: Vec<Answer> = Vec::new();
    for name in names {
        let (thread_name, thread_tx) = (name.clone(), tx.clone());
        let spawned = std::thread::Builder::new()
            .name(format!("estop/{name}"))
            .spawn(move || {
                let _ = thread_tx.send(ask(&thread_name, timeout));
            });
        if let Err(e) = spawned {
            answers.push(Answer {
                name: name.clone(),
                stopped: false,
                pending: false,
                message: format!("could not ask: {e}"),
                answer_ms: None,
            });
        }
    }
    drop(tx);
    let end = deadline(timeout + PENDING_LOOK + Duration::from_millis(500));
    while answers.len() < names.len() {
        let left = Duration::from_nanos(end.saturating_sub(now_ns()));
        match rx.recv_timeout(left) {
            Ok(answer) => answers.push(answer),
            Err(_) => break,
        }
    }
    names
        .iter()
        .map(|name| {
            answers
                .iter()
                .find(|a| &a.name == name)
                .cloned()
                .unwrap_or_else(|| Answer {
                    name: name.clone(),
                    stopped: false,
                    pending: false,
                    message: format!("no answer within {timeout:?}"),
                    answer_ms: None,
                })
        })
        .collect()
}

/// One line per robot, stopped ones marked `stopped`, the others `NOT STOPPED`; a robot whose
/// mirror keeps the e-stop asked says so first, then why it is not stopped yet.
pub fn answer_lines(answers: &[Answer]) -> Vec<String> {
    let width = answers.iter().map(|a| a.name.len()).max().unwrap_or(4);
    answers
        .iter()
        .map(|a| {
            format!(
                "{:<11} {:<width$}  {}{}{}",
                if a.stopped { "stopped" } else { "NOT STOPPED" },
                a.name,
                if a.pending {
                    format!("{PENDING} · ")
                } else {
                    String::new()
                },
                a.message,
                a.answer_ms
                    .map_or(String::new(), |ms| format!(" ({ms} ms)"))
            )
        })
        .collect()
}

/// `chassis control --all estop`: exits non-zero unless every robot found answered stopped.
pub fn estop_all(args: &EstopArgs, json: bool) -> anyhow::Result<std::process::ExitCode> {
    let config = chassis_ipc::config(None)?;
    let names = chassis_ipc::robots(&config)?;
    if names.is_empty() {
        anyhow::bail!(
            "no robot is served on this computer (no chassis/*/state under this IPC prefix): \
             nothing was stopped"
        );
    }
    let timeout = Duration::from_millis(args.timeout_ms.clamp(1, 60_000));
    let answers = estop_robots(&names, timeout);
    let not_stopped = answers.iter().filter(|a| !a.stopped).count();
    let pending = answers.iter().filter(|a| !a.stopped && a.pending).count();
    if json {
        println!(
            "{}",
            serde_json::json!({
                "answers": answers,
                "not_stopped": not_stopped,
                "pending": pending,
            })
        );
    } else {
        for line in answer_lines(&answers) {
            println!("{line}");
        }
    }
    if not_stopped > 0 {
        eprintln!(
            "chassis: {not_stopped} of {} robots NOT stopped: {}",
            answers.len(),
            answers
                .iter()
                .filter(|a| !a.stopped)
                .map(|a| if a.pending {
                    format!("{} (pending)", a.name)
                } else {
                    a.name.clone()
                })
                .collect::<Vec<_>>()
                .join(", ")
        );
        if pending > 0 {
            eprintln!(
                "chassis: the mirror keeps the e-stop asked of {pending} of them and delivers it \
                 when the link returns; until then, stop them by hand"
            );
        }
        return Ok(std::process::ExitCode::FAILURE);
    }
    eprintln!("chassis: all {} robots stopped", answers.len());
    Ok(std::process::ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_that_does_not_answer_is_named_not_stopped() {
        // No robot of these names exists under this prefix: each is reported, none stopped.
        let names = vec!["nosuchrobot1".to_string(), "nosuchrobot2".to_string()];
        let answers = estop_robots(&names, Duration::from_millis(100));
        assert_eq!(answers.len(), 2);
        assert!(answers.iter().all(|a| !a.stopped), "{answers:?}");
        assert!(answers.iter().all(|a| !a.pending), "{answers:?}");
        let lines = answer_lines(&answers);
        assert!(
            lines[0].starts_with("NOT STOPPED nosuchrobot1"),
            "{lines:?}"
        );
    }

    #[test]
    fn a_pending_robot_is_not_stopped_and_says_so() {
        let answer = |name: &str, stopped, pending| Answer {
            name: name.into(),
            stopped,
            pending,
            message: "timeout: no answer".into(),
            answer_ms: Some(1500),
        };
        let lines = answer_lines(&[answer("r1", true, false), answer("r2", false, true)]);
        assert!(lines[0].starts_with("stopped     r1  timeout"), "{lines:?}");
        assert_eq!(
            lines[1],
            format!("NOT STOPPED r2  {PENDING} · timeout: no answer (1500 ms)")
        );
    }
}
