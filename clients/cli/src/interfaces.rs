//! `chassis interfaces`: the IPC contract — services, limits and payload layouts — as a short
//! table, or as the JSON document mirrors in other languages are generated from (`--json`, the
//! content of `interfaces/contract.json`).

use chassis_ipc::contract::{self, Pattern};

#[derive(Debug, clap::Args)]
pub struct InterfacesArgs {
    /// Print the whole contract as JSON (services, limits, every type's fields and constants).
    #[arg(long)]
    json: bool,
}

pub fn run(args: &InterfacesArgs) -> anyhow::Result<()> {
    print!("{}", render(args.json)?);
    Ok(())
}

/// The text `chassis interfaces` prints.
pub fn render(json: bool) -> anyhow::Result<String> {
    if json {
        return Ok(contract::json()?);
    }
    let doc = contract::document();
    let mut lines = vec![
        format!(
            "iceoryx2 prefix: ${} (default {})",
            doc.prefix_env, doc.default_prefix
        ),
        String::new(),
        format!("{:<32} {:<18} payload", "service", "pattern"),
    ];
    for service in &doc.services {
        let (pattern, payload) = match &service.pattern {
            Pattern::PublishSubscribe { payload, limits } => (
                "publish-subscribe",
                format!(
                    "{payload} (history {}, buffer ≤ {}, {} publisher(s), {} subscribers)",
                    limits.history_size,
                    limits.subscriber_max_buffer_size,
                    limits.max_publishers,
                    limits.max_subscribers
                ),
            ),
            Pattern::RequestResponse {
                request,
                response,
                limits,
            } => (
                "request-response",
                format!(
                    "{request} → {response} ({} server, {} clients)",
                    limits.max_servers, limits.max_clients
                ),
            ),
        };
        lines.push(format!("{:<32} {pattern:<18} {payload}", service.name));
    }
    lines.push(String::new());
    lines.push(format!(
        "{:<16} {:<32} {:>5} {:>5} fields",
        "type", "type name", "size", "align"
    ));
    for (name, t) in &doc.types {
        lines.push(format!(
            "{name:<16} {:<32} {:>5} {:>5} {}",
            t.type_name,
            t.size,
            t.align,
            t.fields.len()
        ));
    }
    lines.push(String::new());
    Ok(lines.join("\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_json_describes_chassis_state_byte_for_byte() {
        let v: serde_json::Value = serde_json::from_str(&render(true).unwrap()).unwrap();
        let state = &v["types"]["ChassisState"];
        assert_eq!(state["type_name"], "chassis::ChassisState.v4");
        assert_eq!(state["size"], 904);
        let field = |name: &str| {
            state["fields"]
                .as_array()
                .unwrap()
                .iter()
                .find(|f| f["name"] == name)
                .cloned()
                .unwrap()
        };
        assert_eq!(field("seq")["offset"], 0);
        assert_eq!(field("seq")["type"]["primitive"], "u64");
        assert_eq!(field("group_stamp_ns")["offset"], 32);
        assert_eq!(field("group_stamp_ns")["type"]["kind"], "array");
        assert_eq!(field("group_stamp_ns")["type"]["len"], 24);
        assert_eq!(field("motion")["offset"], 224);
        assert_eq!(field("system")["offset"], 328);
        assert_eq!(field("gps")["offset"], 688);
        assert_eq!(field("link")["offset"], 760);
        assert_eq!(field("link")["type"]["struct"], "LinkStats");
        let state_service = v["services"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == "chassis/{robot}/state")
            .cloned()
            .unwrap();
        assert_eq!(state_service["payload"], "ChassisState");
    }

    #[test]
    fn the_table_names_every_service_and_type() {
        let table = render(false).unwrap();
        assert!(table.contains("chassis/{robot}/cmd/{source}"));
        assert!(table.contains("chassis::ChassisState.v4"));
        assert!(table.contains("CHASSIS_IPC_PREFIX"));
    }
}
