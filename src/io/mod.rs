//! Readers and writers: OBJ, OFF, glTF 2.0 (`.gltf` with embedded buffers, `.glb`).
//!
//! Readers meet untrusted bytes: they never panic and never allocate more than a small
//! multiple of the input's size. They produce a [`RawMesh`]; [`load`] validates it into a
//! [`Mesh`].

pub mod gltf;
pub mod obj;
pub mod off;
pub mod pattern;

use crate::mesh::{Mesh, MeshError, RawMesh, Warning};
use std::path::Path;

/// What one file may expand to, checked before the memory is allocated: a small glTF can
/// instance one mesh thousands of times, an OBJ polygon line fans into many triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Most triangles (after instancing and triangulation) and most vertices.
    pub max_triangles: usize,
}

impl Default for Limits {
    /// The command line's: files are the user's own; the bound only keeps a corrupt count
    /// from exhausting memory.
    fn default() -> Self {
        Limits {
            max_triangles: gltf::MAX_TRIANGLES,
        }
    }
}

thread_local! {
    /// Set while [`quietly`] runs: the hook of [`install_quiet_panic_hook`] stays silent.
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f`, turning a panic into `Err(its message)`. A third-party parser may panic on
/// hostile input; the caller reports that as an error of the input, and (with
/// [`install_quiet_panic_hook`]) nothing is printed for it.
pub fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    QUIET.with(|q| q.set(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(false));
    r.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".into())
    })
}

/// Keep the process's panic hook, except for panics inside [`quietly`], which are reported
/// as errors of the input instead (the command line prints one line per failure).
pub fn install_quiet_panic_hook() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !QUIET.with(|q| q.get()) {
            previous(info);
        }
    }));
}

/// Names (patches, objects, groups) longer than this many bytes are cut, with a warning.
pub const MAX_NAME_BYTES: usize = 256;

/// `name` cut to at most [`MAX_NAME_BYTES`] bytes, on a character boundary.
pub fn cap_name(name: &str) -> (&str, bool) {
    if name.len() <= MAX_NAME_BYTES {
        return (name, false);
    }
    let mut end = MAX_NAME_BYTES;
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    (&name[..end], true)
}

/// A mesh file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Wavefront OBJ.
    Obj,
    /// Object File Format.
    Off,
    /// glTF 2.0 JSON with embedded `data:` buffers.
    Gltf,
    /// Binary glTF 2.0.
    Glb,
}

impl Format {
    /// The format named by a file extension (case-insensitive).
    pub fn from_extension(ext: &str) -> Option<Format> {
        match ext.to_ascii_lowercase().as_str() {
            "obj" => Some(Format::Obj),
            "off" => Some(Format::Off),
            "gltf" => Some(Format::Gltf),
            "glb" => Some(Format::Glb),
            _ => None,
        }
    }

    /// The format of a path, by extension, else by content.
    pub fn of_path(path: &Path, bytes: &[u8]) -> Option<Format> {
        path.extension()
            .and_then(|e| e.to_str())
            .and_then(Format::from_extension)
            .or_else(|| Format::sniff(bytes))
    }

    /// Guess the format from the first bytes.
    pub fn sniff(bytes: &[u8]) -> Option<Format> {
        if bytes.starts_with(b"glTF") {
            return Some(Format::Glb);
        }
        let head = &bytes[..bytes.len().min(4096)];
        let text = String::from_utf8_lossy(head);
        let t = text.trim_start_matches('\u{feff}').trim_start();
        if t.starts_with('{') {
            return Some(Format::Gltf);
        }
        if t.starts_with("OFF") || t.starts_with("COFF") || t.starts_with("NOFF") {
            return Some(Format::Off);
        }
        if t.lines().any(|l| {
            let l = l.trim_start();
            l.starts_with("v ") || l.starts_with("f ") || l.starts_with('#')
        }) {
            return Some(Format::Obj);
        }
        None
    }

    /// The usual extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Obj => "obj",
            Format::Off => "off",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
        }
    }
}

/// Why a file could not be read. Every variant says where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReadError {
    /// A text format's syntax error.
    #[error("{format} line {line}: {message}")]
    Syntax {
        /// `OBJ` or `OFF`.
        format: &'static str,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A glTF problem, with the JSON path or element concerned.
    #[error("glTF: {0}")]
    Gltf(String),
    /// The format could not be recognised.
    #[error("unrecognised mesh format (expected .obj, .off, .gltf or .glb)")]
    UnknownFormat,
    /// The geometry was read but is not a valid mesh.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The file could not be read.
    #[error("{0}")]
    Io(String),
    /// The file expands to more than the limit allows.
    #[error("{what}: more than the {limit} allowed")]
    TooLarge {
        /// What was counted, and where (e.g. `triangles after instancing 400 nodes`).
        what: String,
        /// The limit passed.
        limit: usize,
    },
}

/// Parse bytes of a known format into raw mesh data.
pub fn read(bytes: &[u8], format: Format) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    read_limited(bytes, format, &Limits::default())
}

/// [`read`] within `limits`.
pub fn read_limited(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    match format {
        Format::Obj => obj::read_limited(bytes, limits),
        Format::Off => off::read_limited(bytes, limits),
        Format::Gltf | Format::Glb => gltf::read_limited(bytes, limits),
    }
}

/// Parse and validate: the one entry point from bytes to a [`Mesh`].
pub fn load(bytes: &[u8], format: Format) -> Result<(Mesh, Vec<Warning>), ReadError> {
    load_limited(bytes, format, &Limits::default())
}

/// [`load`] within `limits`.
pub fn load_limited(
    bytes: &[u8],
    format: Format,
    limits: &Limits,
) -> Result<(Mesh, Vec<Warning>), ReadError> {
    let (raw, mut warnings) = read_limited(bytes, format, limits)?;
    let (mesh, w) = Mesh::new(raw)?;
    warnings.extend(w);
    Ok((mesh, warnings))
}

/// Read and validate a mesh file, choosing the format by extension or content.
pub fn load_path(path: &Path) -> Result<(Mesh, Vec<Warning>), ReadError> {
    let bytes =
        std::fs::read(path).map_err(|e| ReadError::Io(format!("{}: {e}", path.display())))?;
    let format = Format::of_path(path, &bytes).ok_or(ReadError::UnknownFormat)?;
    load(&bytes, format)
}
