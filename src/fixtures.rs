//! Procedural meshes with known answers (being written).
