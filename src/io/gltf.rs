//! glTF 2.0 reader and GLB writer (being written).

use super::ReadError;
use crate::mesh::{RawMesh, Warning};

/// Parse `.gltf` (embedded buffers) or `.glb` bytes.
pub fn read(_bytes: &[u8]) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    Err(ReadError::Gltf("not implemented yet".into()))
}

/// GLB writer (being written).
pub fn write_glb(_mesh: &crate::mesh::Mesh, _flattenability: Option<&[f64]>) -> Vec<u8> {
    Vec::new()
}
