//! Blobs as files under one directory, written to a temporary name and renamed into place
//! (atomic on one file system).

use super::{Blobs, StoreError};
use std::path::PathBuf;

/// Files under `root`, one per key (`jobs/{id}` is a directory).
#[derive(Debug, Clone)]
pub struct FileBlobs {
    root: PathBuf,
}

impl FileBlobs {
    /// Blobs under `root` (created on first write).
    pub fn new(root: PathBuf) -> FileBlobs {
        FileBlobs { root }
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
        let io = |e| StoreError::Io(key.to_string(), e);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        std::fs::write(&tmp, bytes).map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)?;
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
