//! The files iceoryx2 keeps for a prefix ([`crate::IPC_PREFIX_ENV`]): its shared-memory segments
//! and its service, node and socket files. A test or a bench that runs under a prefix of its own
//! lists or removes them through here when it ends.

use std::os::unix::fs::MetadataExt;
use std::path::PathBuf;

/// Where iceoryx2 keeps the files of a prefix: POSIX shared memory, and its own folders.
const DIRS: [&str; 4] = [
    "/dev/shm",
    "/tmp/iceoryx2",
    "/tmp/iceoryx2/services",
    "/tmp/iceoryx2/nodes",
];

/// The files and folders of the iceoryx2 prefix `prefix`.
pub fn ipc_files(prefix: &str) -> Vec<PathBuf> {
    DIRS.iter()
        .flat_map(|dir| std::fs::read_dir(dir).into_iter().flatten().flatten())
        .filter(|entry| entry.file_name().to_string_lossy().starts_with(prefix))
        .map(|entry| entry.path())
        .collect()
}

/// Removes the files and folders of the iceoryx2 prefix `prefix`; returns those that could not
/// be removed, with why.
pub fn remove_ipc_files(prefix: &str) -> Vec<(PathBuf, std::io::Error)> {
    ipc_files(prefix)
        .into_iter()
        .filter_map(|path| {
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            match removed {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => Some((path, e)),
                _ => None,
            }
        })
        .collect()
}

/// iceoryx2's folder in /tmp (or one inside it) when it belongs to another user than this
/// process's: made by whichever program of any user ran first, closed to the others, it keeps
/// every other user's programs out. The folder and its owner's name.
pub fn foreign_folder() -> Option<(PathBuf, String)> {
    let me = std::fs::metadata("/proc/self").ok()?.uid();
    DIRS[1..].iter().find_map(|dir| {
        let owner = std::fs::metadata(dir).ok()?.uid();
        (owner != me).then(|| (PathBuf::from(dir), user_name(owner)))
    })
}

/// The name of the user `uid` (/etc/passwd), else `uid N`.
pub fn user_name(uid: u32) -> String {
    let passwd = std::fs::read_to_string("/etc/passwd").unwrap_or_default();
    passwd_name(&passwd, uid).map_or_else(|| format!("uid {uid}"), str::to_string)
}

/// The name of `uid` in the text of /etc/passwd.
fn passwd_name(passwd: &str, uid: u32) -> Option<&str> {
    passwd.lines().find_map(|line| {
        let fields: Vec<&str> = line.split(':').collect();
        (fields.len() > 2 && fields[2].parse() == Ok(uid)).then_some(fields[0])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_user_is_named_by_passwd() {
        let passwd =
            "root:x:0:0:root:/root:/bin/bash\nchassis:x:998:998::/nonexistent:/usr/sbin/nologin\n";
        assert_eq!(passwd_name(passwd, 998), Some("chassis"));
        assert_eq!(passwd_name(passwd, 1000), None);
    }
}
