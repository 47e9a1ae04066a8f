//! Robot and source names, which become service names (`chassis-ipc` builds those) and
//! fixed-length fields.

/// Robot and source names: 1 to 16 characters of `a-z`, `0-9`, `-`, `_` (they become service
/// names and fixed-length fields).
pub fn valid_robot_name(name: &str) -> bool {
    (1..=crate::NAME_LEN).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_names_are_checked() {
        assert!(valid_robot_name("scout-mini"));
        assert!(valid_robot_name("bot_2"));
        assert!(!valid_robot_name(""));
        assert!(!valid_robot_name("Titan"));
        assert!(!valid_robot_name("a/b"));
        assert!(!valid_robot_name("seventeen-chars-x"));
    }
}
