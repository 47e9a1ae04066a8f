//! The files iceoryx2 keeps for a prefix ([`crate::IPC_PREFIX_ENV`]): its shared-memory segments
//! and its service, node and socket files. A test or a bench that runs under a prefix of its own
//! lists or removes them through here when it ends.

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
