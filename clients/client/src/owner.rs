//! Which user a robot's chassisd runs as. iceoryx2's shared memory, sockets and folders belong to
//! the user who created them (its folder in /tmp is closed to others), so every program of a
//! robot runs as chassisd's user; a client of another user is told so before it touches them.

/// The user of the chassisd serving `robot` (`--name robot` on its command line), when that is
/// not this process's effective user: its name from /etc/passwd, else `uid N`.
pub(crate) fn other_users_chassisd(robot: &str) -> Option<String> {
    let me = effective_uid(&std::fs::read_to_string("/proc/self/status").ok()?)?;
    let uid = std::fs::read_dir("/proc")
        .ok()?
        .flatten()
        .filter(|entry| {
            entry
                .file_name()
                .to_string_lossy()
                .bytes()
                .all(|b| b.is_ascii_digit())
        })
        .filter(|entry| {
            serves(
                &std::fs::read(entry.path().join("cmdline")).unwrap_or_default(),
                robot,
            )
        })
        .find_map(|entry| {
            let status = std::fs::read_to_string(entry.path().join("status")).ok()?;
            effective_uid(&status).filter(|&uid| uid != me)
        })?;
    Some(chassis_ipc::user_name(uid))
}

/// A command line (NUL-separated, as /proc/PID/cmdline) of chassisd serving `robot`.
fn serves(cmdline: &[u8], robot: &str) -> bool {
    let args: Vec<&[u8]> = cmdline.split(|&b| b == 0).collect();
    let chassisd = args
        .first()
        .is_some_and(|program| program.rsplit(|&b| b == b'/').next() == Some(b"chassisd"));
    let named = args
        .windows(2)
        .any(|w| w[0] == b"--name" && w[1] == robot.as_bytes())
        || args
            .iter()
            .any(|arg| *arg == format!("--name={robot}").as_bytes());
    chassisd && named
}

/// The effective uid in the text of /proc/PID/status (`Uid: real effective saved fs`).
fn effective_uid(status: &str) -> Option<u32> {
    status
        .lines()
        .find_map(|line| line.strip_prefix("Uid:"))
        .and_then(|ids| ids.split_whitespace().nth(1))
        .and_then(|uid| uid.parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chassisd_serves_the_robot_named_on_its_command_line() {
        assert!(serves(
            b"/usr/bin/chassisd\0--config\0/etc/chassisd/r1.toml\0--name\0r1\0",
            "r1"
        ));
        assert!(serves(b"chassisd\0--name=r1\0", "r1"));
        assert!(!serves(b"/usr/bin/chassisd\0--name\0r10\0", "r1"));
        assert!(!serves(b"/usr/bin/chassis\0status\0--name\0r1\0", "r1"));
        assert!(!serves(b"", "r1"));
    }

    #[test]
    fn the_user_is_the_effective_one() {
        let status = "Name:\tchassisd\nUid:\t0\t998\t998\t998\nGid:\t0\t998\t998\t998\n";
        assert_eq!(effective_uid(status), Some(998));
        assert_eq!(effective_uid("Name:\tx\n"), None);
    }
}
