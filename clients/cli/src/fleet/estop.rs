//! `chassis control --all estop`: the operator's e-stop on every robot served on this computer,
//! asked of all of them at once, each answer listed.
//!
//! A robot counts as stopped only when its chassisd answered the request with success (the
//! lock is then held, and written to its lock file, before the answer). No answer within the
//! bound, a refusal, a mirror that could not reach the robot, a robot that cannot be opened: the
//! robot is named NOT stopped, and the command exits non-zero. A robot whose thread is still
//! waiting when the bound is over is named NOT stopped too, never left out.

use std::sync::mpsc;
use std::time::Duration;

use chassis_client::{ControlKind, ControlRequest, ControlStatus, Robot, now_ns};
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
    /// chassisd's message, or why there is no stop.
    pub message: String,
    pub answer_ms: Option<u64>,
}

fn ask(name: &str, timeout: Duration) -> Answer {
    let start = now_ns();
    let answered = |stopped: bool, message: String| Answer {
        name: name.to_string(),
        stopped,
        message,
        answer_ms: Some(now_ns().saturating_sub(start) / 1_000_000),
    };
    let mut robot = match Robot::connect(name) {
        Ok(robot) => robot,
        Err(e) => return answered(false, format!("cannot reach it: {e}")),
    };
    let request = ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop");
    match robot.control(request, timeout) {
        Ok(response) if response.is_ok() => answered(true, response.message().to_string()),
        Ok(response) => answered(
            false,
            format!(
                "{}: {}",
                ControlStatus::name(response.status),
                response.message()
            ),
        ),
        Err(e) => answered(false, e.to_string()),
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
                message: format!("could not ask: {e}"),
                answer_ms: None,
            });
        }
    }
    drop(tx);
    let deadline = now_ns().saturating_add(
        u64::try_from((timeout + Duration::from_millis(500)).as_nanos()).unwrap_or(u64::MAX),
    );
    while answers.len() < names.len() {
        let left = Duration::from_nanos(deadline.saturating_sub(now_ns()));
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
                    message: format!("no answer within {timeout:?}"),
                    answer_ms: None,
                })
        })
        .collect()
}

/// One line per robot, stopped ones first marked `stopped`, the others `NOT STOPPED`.
pub fn answer_lines(answers: &[Answer]) -> Vec<String> {
    let width = answers.iter().map(|a| a.name.len()).max().unwrap_or(4);
    answers
        .iter()
        .map(|a| {
            format!(
                "{:<11} {:<width$}  {}{}",
                if a.stopped { "stopped" } else { "NOT STOPPED" },
                a.name,
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
    if json {
        println!(
            "{}",
            serde_json::json!({ "answers": answers, "not_stopped": not_stopped })
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
                .map(|a| a.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
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
        let lines = answer_lines(&answers);
        assert!(
            lines[0].starts_with("NOT STOPPED nosuchrobot1"),
            "{lines:?}"
        );
    }
}
