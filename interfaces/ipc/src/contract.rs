//! The machine-readable contract: every service with its name pattern, payload and limits, the
//! prefix variable, and the layout of every payload type and of its constants.
//!
//! `chassis interfaces --json` prints it; `interfaces/contract.json` is the committed copy that
//! mirrors in other languages are generated from (a test keeps it equal to [`json`]). Everything
//! is sorted, so the document changes only when the contract does.

use std::collections::BTreeMap;

use chassis_interfaces::SafetyStatus;
use chassis_interfaces::layout::{self, ConstantGroup, Layout, TypeLayout};
use iceoryx2::prelude::Config;
use serde::Serialize;

use crate::limits::{EventLimits, PubSubLimits, RequestResponseLimits};
use crate::{
    CMD, CONTROL, DESCRIPTION, FRAMES, IPC_PREFIX_ENV, MUX, PubSub, REPLY_SUFFIX, RequestResponse,
    SIM, STATE, ServiceKind, publication, reply_name, service_name,
};

/// Version of the document's shape (not of the types: each type name carries its own).
pub const VERSION: u32 = 1;

/// Placeholders of the name patterns.
const ROBOT: &str = "{robot}";
const SOURCE: &str = "{source}";

/// The whole contract.
#[derive(Debug, Serialize)]
pub struct Document {
    pub version: u32,
    /// The environment variable naming the iceoryx2 file prefix.
    pub prefix_env: &'static str,
    /// The prefix when the variable is not set.
    pub default_prefix: String,
    /// What the reply event's name appends to a request-response service's name.
    pub reply_suffix: &'static str,
    /// Every service, by name pattern.
    pub services: Vec<Service>,
    /// Every payload type and every type nested in one, by Rust name.
    pub types: BTreeMap<&'static str, TypeLayout>,
    /// Flag and enumeration constants, by group name.
    pub constants: BTreeMap<&'static str, ConstantGroup>,
}

/// One service.
#[derive(Debug, Serialize)]
pub struct Service {
    /// Name pattern, e.g. `chassis/{robot}/cmd/{source}`.
    pub name: String,
    /// The process that creates it (and so fixes its limits).
    pub created_by: &'static str,
    #[serde(flatten)]
    pub pattern: Pattern,
    /// Its event services.
    pub events: Vec<Event>,
}

/// The messaging pattern, payload types and limits of a service.
#[derive(Debug, Serialize)]
#[serde(tag = "pattern", rename_all = "snake_case")]
pub enum Pattern {
    PublishSubscribe {
        payload: &'static str,
        limits: PubSubLimits,
    },
    RequestResponse {
        request: &'static str,
        response: &'static str,
        limits: RequestResponseLimits,
    },
}

/// An event service paired with a service.
#[derive(Debug, Serialize)]
pub struct Event {
    pub name: String,
    /// Who notifies, and why.
    pub notified_by: &'static str,
    #[serde(flatten)]
    pub limits: EventLimits,
}

fn topic<T: Layout>(spec: &PubSub<T>, kind: ServiceKind<'_>, created_by: &'static str) -> Service {
    let name = service_name(ROBOT, kind);
    Service {
        events: vec![Event {
            name: name.clone(),
            notified_by: "the publisher, after sending",
            limits: spec.limits.event,
        }],
        name,
        created_by,
        pattern: Pattern::PublishSubscribe {
            payload: T::NAME,
            limits: spec.limits,
        },
    }
}

fn desk<Req: Layout>(
    spec: &RequestResponse<Req>,
    kind: ServiceKind<'_>,
    created_by: &'static str,
) -> Service {
    let name = service_name(ROBOT, kind);
    Service {
        events: vec![
            Event {
                name: name.clone(),
                notified_by: "a client, after sending a request",
                limits: spec.limits.request_event,
            },
            Event {
                name: reply_name(&name),
                notified_by: "the server, after answering",
                limits: spec.limits.reply_event,
            },
        ],
        name,
        created_by,
        pattern: Pattern::RequestResponse {
            request: Req::NAME,
            response: chassis_interfaces::ControlResponse::NAME,
            limits: spec.limits,
        },
    }
}

/// The contract as it is in this build.
pub fn document() -> Document {
    let mut services = vec![
        topic(&STATE, ServiceKind::State, "chassisd"),
        topic(&FRAMES, ServiceKind::Frames, "chassisd"),
        topic(&MUX, ServiceKind::Mux, "chassisd"),
        topic(&DESCRIPTION, ServiceKind::Description, "chassisd"),
        topic(
            &CMD,
            ServiceKind::Cmd(SOURCE),
            "chassisd (one per configured source)",
        ),
        desk(&CONTROL, ServiceKind::Control, "chassisd"),
        desk(
            &SIM,
            ServiceKind::Sim,
            "the simulated chassis (chassisd with the simulated bus, or chassisd sim)",
        ),
        topic(
            &publication::<SafetyStatus>(),
            ServiceKind::Publication(SafetyStatus::SERVICE),
            "chassis-safety",
        ),
    ];
    services.sort_by(|a, b| a.name.cmp(&b.name));
    Document {
        version: VERSION,
        prefix_env: IPC_PREFIX_ENV,
        default_prefix: Config::default().global.prefix.to_string(),
        reply_suffix: REPLY_SUFFIX,
        services,
        types: layout::types().into_iter().map(|t| (t.name, t)).collect(),
        constants: layout::constants()
            .into_iter()
            .map(|g| (g.name, g))
            .collect(),
    }
}

/// [`document`] as pretty-printed JSON, with a final newline: the content of
/// `interfaces/contract.json`.
pub fn json() -> Result<String, serde_json::Error> {
    let mut text = serde_json::to_string_pretty(&document())?;
    text.push('\n');
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value() -> serde_json::Value {
        serde_json::from_str(&json().unwrap()).unwrap()
    }

    #[test]
    fn the_committed_contract_is_the_one_the_code_describes() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../contract.json");
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed == json().unwrap(),
            "interfaces/contract.json differs from the contract the code describes; regenerate \
             it with `cargo run -q -p chassis-cli --bin chassis -- interfaces --json > \
             interfaces/contract.json` and review the difference"
        );
    }

    #[test]
    fn every_payload_is_a_described_type() {
        let doc = document();
        for service in &doc.services {
            let names = match &service.pattern {
                Pattern::PublishSubscribe { payload, .. } => vec![*payload],
                Pattern::RequestResponse {
                    request, response, ..
                } => vec![*request, *response],
            };
            for name in names {
                assert!(doc.types.contains_key(name), "{}: {name}", service.name);
            }
        }
    }

    #[test]
    fn services_carry_their_patterns_and_limits() {
        let v = value();
        assert_eq!(v["version"], VERSION);
        assert_eq!(v["prefix_env"], "CHASSIS_IPC_PREFIX");
        let services = v["services"].as_array().unwrap();
        let names: Vec<&str> = services
            .iter()
            .map(|s| s["name"].as_str().unwrap())
            .collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        assert_eq!(names, sorted);
        let state = services
            .iter()
            .find(|s| s["name"] == "chassis/{robot}/state")
            .unwrap();
        assert_eq!(state["pattern"], "publish_subscribe");
        assert_eq!(state["payload"], "ChassisState");
        assert_eq!(state["limits"]["subscriber_max_buffer_size"], 256);
        assert_eq!(state["limits"]["max_publishers"], 1);
        assert_eq!(state["limits"]["safe_overflow"], true);
        assert_eq!(state["events"][0]["max_listeners"], 40);
        let control = services
            .iter()
            .find(|s| s["name"] == "chassis/{robot}/control")
            .unwrap();
        assert_eq!(control["request"], "ControlRequest");
        assert_eq!(control["response"], "ControlResponse");
        assert_eq!(
            control["events"][1]["name"],
            "chassis/{robot}/control/reply"
        );
        assert!(names.contains(&"chassis/{robot}/cmd/{source}"));
        assert!(names.contains(&"chassis/{robot}/safety"));
    }

    #[test]
    fn types_and_constants_are_listed_with_their_layouts() {
        let v = value();
        let state = &v["types"]["ChassisState"];
        assert_eq!(state["type_name"], "chassis::ChassisState.v4");
        assert_eq!(state["size"], 904);
        assert_eq!(state["align"], 8);
        let motion = &state["fields"][7];
        assert_eq!(motion["name"], "motion");
        assert_eq!(motion["offset"], 224);
        assert_eq!(motion["type"]["kind"], "struct");
        assert_eq!(motion["type"]["struct"], "MotionState");
        assert_eq!(v["types"]["VelocityRequest"]["size"], 64);
        assert_eq!(
            v["constants"]["ControlStatus"]["values"][1]["name"],
            "REFUSED"
        );
        assert_eq!(v["constants"]["FaultFlags"]["type"], "u64");
    }
}
