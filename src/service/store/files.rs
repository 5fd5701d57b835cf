//! Blobs as files under one directory, written to a temporary name and renamed into place
//! (atomic on one file system).

use super::{Blobs, StoreError};
use std::path::PathBuf;

/// Files under `root`, one per key (`jobs/{id}` is a directory).
#[derive(Debug, Clone)]
pub struct FileBlobs {
    root: PathBuf,
}

/// Extension prefix of a blob being written (`.tmp<pid>`).
const TMP: &str = "tmp";

impl FileBlobs {
    /// Blobs under `root` (created on first write).
    pub fn new(root: PathBuf) -> FileBlobs {
        FileBlobs { root }
    }

    /// Delete blobs a process left half-written when it died (`*.tmp<pid>` of a process
    /// that no longer runs; processes sharing the directory keep theirs): none is referenced,
    /// and each holds space. Returns how many went. Linux only (it asks /proc).
    pub fn sweep_temporary(&self) -> usize {
        if !std::path::Path::new("/proc/self").exists() {
            return 0;
        }
        let mut gone = 0;
        let mut stack = vec![self.root.clone()];
        while let Some(dir) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                    continue;
                }
                let dead_writer = p
                    .extension()
                    .and_then(|x| x.to_str())
                    .and_then(|x| x.strip_prefix(TMP))
                    .and_then(|pid| pid.parse::<u32>().ok())
                    .is_some_and(|pid| {
                        // This process has written nothing yet: a file with its id is from an
                        // earlier process that had the same one (PID 1 in a container).
                        pid == std::process::id()
                            || !std::path::Path::new(&format!("/proc/{pid}")).exists()
                    });
                if dead_writer && std::fs::remove_file(&p).is_ok() {
                    gone += 1;
                }
            }
        }
        gone
    }

    fn blob_path(&self, key: &str) -> PathBuf {
        // Keys are built by the service from generated ids; refuse anything that could escape.
        let clean: String = key
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/') {
                    c
                } else {
                    '_'
                }
            })
            .collect::<String>()
            .replace("..", "__");
        self.root.join(clean)
    }
}

impl Blobs for FileBlobs {
    fn put_blob(&self, key: &str, bytes: &[u8]) -> Result<(), StoreError> {
        let path = self.blob_path(key);
        let io = |e: std::io::Error| {
            if super::is_full(&e) {
                StoreError::Full(format!("no space for blob {key}"))
            } else {
                StoreError::Io(key.to_string(), e)
            }
        };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let tmp = path.with_extension(format!("{TMP}{}", std::process::id()));
        let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, &path));
        if let Err(e) = written {
            // A partial file would hold the space a full disk lacks.
            let _ = std::fs::remove_file(&tmp);
            return Err(io(e));
        }
        Ok(())
    }

    fn get_blob(&self, key: &str) -> Result<Option<Vec<u8>>, StoreError> {
        match std::fs::read(self.blob_path(key)) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StoreError::Io(key.to_string(), e)),
        }
    }

    fn delete_blobs(&self, prefix: &str) -> Result<(), StoreError> {
        let path = self.blob_path(prefix);
        let r = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        match r {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(StoreError::Io(prefix.to_string(), e)),
        }
    }
}
