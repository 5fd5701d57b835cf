//! glTF 2.0 reader (`.gltf` with embedded `data:` buffers, and `.glb`) and writer (GLB and
//! `.gltf` with an embedded buffer).
//!
//! Reading: the `gltf` crate parses and validates the JSON (it panics on some malformed input,
//! ../shared/CRATES.md, so the call is guarded by `catch_unwind`). Buffer data is then read
//! here, not through the crate's reader: every accessor we use is bounds-checked against its
//! buffer view and buffer with checked arithmetic *before* anything is allocated, so an
//! accessor claiming 2³² elements is refused instead of allocated. External and `file:` URIs
//! are never followed.
//!
//! Assembly: every TRIANGLES primitive of the default scene becomes one patch, with node
//! transforms applied (a mirroring transform reverses the winding so normals stay outward).
//! Vertices live in *spaces*: one per (node, POSITION accessor) for indexed primitives, so
//! primitives that share an accessor share vertices exactly as the file says, and one per
//! non-indexed primitive, whose corners are joined when their positions are bit-identical
//! (a non-indexed primitive has no other way to say two corners are one vertex). Across
//! spaces, border vertices (on an edge used once within their space) that coincide within
//! [`WELD_RELATIVE`] × the bounding-box diagonal are welded, so that panels exported as
//! separate primitives stay connected along their seams. Within a space nothing is welded: an
//! indexed file's own connectivity (a cut, say) is respected.
//!
//! Writing: one POSITION, NORMAL, `_FLATTENABILITY` and COLOR_0 accessor for all vertices
//! (and, for `perturb`, `_DISPLACEMENT`: a [`VertexScalar`]), in the mesh's vertex order, and one primitive per patch with its own indices, so that a
//! written file reads back with the same vertex numbering and patches. A mesh with texture
//! coordinates (a flattened one: each corner at its point in the pattern drawing) is written
//! with TEXCOORD_0; when a vertex has several coordinates (pieces meet, or a real cut), as one
//! vertex set per patch, a vertex once per coordinate it has there, with `_VERTEX_ID` naming
//! the mesh vertex each copy is; reading joins the copies by it (the mesh's own numbering and
//! connectivity again; a file without it is welded as before). TEXCOORD_0 is read back into
//! the mesh's texture coordinates (v flipped, glTF's origin being the top left). glTF stores positions
//! as f32; use OBJ when full f64 precision matters. The JSON is built with `serde_json` and the
//! GLB container (a 12-byte header and two padded chunks) is written here, which keeps the
//! alignment rules in plain sight.

use super::ReadError;
use crate::geometry;
use crate::mesh::{Mesh, RawMesh, Warning};
use base64::Engine;
use std::collections::HashMap;

/// Coincident border vertices of different spaces are welded within this fraction of the
/// bounding-box diagonal. f32 positions carry a relative error near 6e-8, and a node transform
/// adds a few more ulps; 1e-6 is well above that and well below any real edge.
pub const WELD_RELATIVE: f64 = 1e-6;

/// The most triangles (after instancing) a file may produce; bounds memory on hostile input.
pub const MAX_TRIANGLES: usize = 1 << 25;

/// Custom attribute naming the mesh vertex each written vertex is a copy of (written when
/// texture coordinates split vertices; read to join them again).
pub const VERTEX_ID: &str = "_VERTEX_ID";

/// ϖ at or below this is the coolest colour of the heat map (the developable tolerance).
pub const HEATMAP_MIN: f64 = geometry::DEVELOPABLE_TOLERANCE;
/// ϖ at or above this (radians) is the hottest colour.
pub const HEATMAP_MAX: f64 = 1.0;
/// Colour of vertices where ϖ is not defined (boundary, seam, unreferenced).
const NON_INTERIOR_COLOR: [f32; 3] = [0.6, 0.6, 0.6];

fn err(msg: impl Into<String>) -> ReadError {
    ReadError::Gltf(msg.into())
}

/// Parse `.gltf` (embedded buffers) or `.glb` bytes.
pub fn read(bytes: &[u8]) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    read_limited(bytes, &super::Limits::default())
}

/// [`read`] within `limits`: what the scene expands to (instances × primitives) is counted
/// from the accessors before any of it is read.
pub fn read_limited(
    bytes: &[u8],
    limits: &super::Limits,
) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    let parsed = super::quietly(|| parse(bytes));
    let (doc, dropped) = match parsed {
        Ok(Ok(doc)) => doc,
        Ok(Err(e)) => return Err(err(describe_gltf_error(&e))),
        Err(why) => {
            return Err(err(format!(
                "malformed document (the glTF parser failed on it: {why})"
            )))
        }
    };
    let decoded = resolve_buffers(&doc)?;
    let blob = doc.blob.as_deref().unwrap_or_default();
    // Buffers without a uri all view the one binary chunk: borrowed, never copied.
    let buffers: Vec<&[u8]> = decoded
        .iter()
        .map(|d| d.as_deref().unwrap_or(blob))
        .collect();
    check_expansion(&doc, &buffers, limits)?;
    let (raw, mut warnings) = assemble(&doc, &buffers, limits)?;
    if !dropped.is_empty() {
        warnings.push(Warning::new(
            "extensions_ignored",
            format!(
                "required extensions ignored (they concern materials, a texture transform or lights, \
                 not geometry): {}",
                dropped.join(", ")
            ),
        ));
    }
    Ok((raw, warnings))
}

/// Whether a required extension only changes how the model looks (materials, a texture
/// transform, lights), never its geometry: such a requirement is dropped, not refused, so
/// that a garment exported with, say, a sheen material still loads. Those that change
/// geometry (Draco, meshopt, quantization), and those that replace a texture's image source
/// (basisu, webp, avif: the document is not valid glTF without them), stay required and
/// are refused by name.
fn looks_only(extension: &str) -> bool {
    extension.starts_with("KHR_materials_")
        || matches!(extension, "KHR_texture_transform" | "KHR_lights_punctual")
}

/// The validated document, and the required extensions dropped by [`looks_only`].
fn parse(bytes: &[u8]) -> Result<(gltf::Gltf, Vec<String>), gltf::Error> {
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(bytes)?;
    let mut root = document.into_json();
    let (dropped, kept) = std::mem::take(&mut root.extensions_required)
        .into_iter()
        .partition(|e| looks_only(e));
    root.extensions_required = kept;
    let document = gltf::Document::from_json(root)?;
    Ok((gltf::Gltf { document, blob }, dropped))
}

/// Refuse a scene that expands past `limits`, counting from accessor counts alone (each
/// checked against its buffer first, so that a forged count is named as such): every
/// instance of a mesh and every primitive sharing an accessor counts again.
fn check_expansion(
    doc: &gltf::Gltf,
    buffers: &[&[u8]],
    limits: &super::Limits,
) -> Result<(), ReadError> {
    let instances = scene_instances(doc)?;
    let (mut triangles, mut vertices, mut primitives) = (0usize, 0usize, 0usize);
    let mut spaces: std::collections::HashSet<(usize, usize)> = Default::default();
    let too_large = |n: usize, what: &str| ReadError::TooLarge {
        what: format!(
            "the scene expands to more than {n} {what} ({} mesh instances)",
            instances.len()
        ),
        limit: limits.max_triangles,
    };
    for inst in &instances {
        for prim in inst.mesh.primitives() {
            // Every instance of every primitive costs something, skipped ones included.
            primitives += 1;
            if primitives > limits.max_triangles {
                return Err(too_large(primitives - 1, "primitives"));
            }
            if prim.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let Some(pos) = prim.get(&gltf::Semantic::Positions) else {
                continue;
            };
            span(&pos, buffers, pos.size(), 1)?;
            if let Some(i) = prim.indices() {
                span(&i, buffers, i.size(), 1)?;
            }
            let corners = prim.indices().map_or(pos.count(), |i| i.count());
            triangles = triangles.saturating_add(corners / 3);
            // Indexed primitives of one node share their POSITION accessor's vertices.
            if prim.indices().is_none() || spaces.insert((inst.node, pos.index())) {
                vertices = vertices.saturating_add(pos.count());
            }
            // Refused as soon as it is known, not after counting a hostile scene through.
            for (n, what) in [(triangles, "triangles"), (vertices, "vertices")] {
                if n > limits.max_triangles {
                    return Err(too_large(limits.max_triangles, what));
                }
            }
        }
    }
    Ok(())
}

fn describe_gltf_error(e: &gltf::Error) -> String {
    match e {
        gltf::Error::Validation(list) => {
            let shown: Vec<String> = list
                .iter()
                .take(3)
                .map(|(path, e)| format!("{}: {e}", path.as_str()))
                .collect();
            let more = if list.len() > 3 {
                format!(" (and {} more)", list.len() - 3)
            } else {
                String::new()
            };
            format!("invalid document: {}{more}", shown.join("; "))
        }
        other => format!("cannot parse: {other}"),
    }
}

/// Buffer data by index: a decoded `data:` URI, or `None` for the GLB binary chunk (which
/// every uri-less buffer views, so it is not copied per buffer).
fn resolve_buffers(doc: &gltf::Gltf) -> Result<Vec<Option<Vec<u8>>>, ReadError> {
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let (data, len) = match buffer.source() {
            gltf::buffer::Source::Bin => {
                let blob = doc
                    .blob
                    .as_deref()
                    .ok_or_else(|| err(format!("buffers[{i}]: no uri and no GLB binary chunk")))?;
                (None, blob.len())
            }
            gltf::buffer::Source::Uri(uri) => {
                let d = decode_data_uri(uri).map_err(|m| err(format!("buffers[{i}]: {m}")))?;
                let n = d.len();
                (Some(d), n)
            }
        };
        if len < buffer.length() {
            return Err(err(format!(
                "buffers[{i}]: byteLength is {} but only {len} bytes of data are present",
                buffer.length(),
            )));
        }
        out.push(data);
    }
    Ok(out)
}

fn decode_data_uri(uri: &str) -> Result<Vec<u8>, String> {
    let Some(rest) = uri.strip_prefix("data:") else {
        let shown: String = uri.chars().take(60).collect();
        return Err(format!(
            "external URI `{shown}` is not followed; embed buffers as data: URIs or send a .glb"
        ));
    };
    let Some(pos) = rest.find(";base64,") else {
        return Err("data: URI is not base64-encoded".into());
    };
    base64::engine::general_purpose::STANDARD
        .decode(&rest[pos + 8..])
        .map_err(|e| format!("data: URI is not valid base64 ({e})"))
}

/// Element layout of an accessor, checked against its view and buffer.
struct Span<'a> {
    data: &'a [u8],
    stride: usize,
    count: usize,
}

/// Bounds-check an accessor of `components` × `component_size` bytes per element and return
/// its bytes, or say precisely what does not fit.
fn span<'a>(
    accessor: &gltf::Accessor,
    buffers: &[&'a [u8]],
    component_size: usize,
    components: usize,
) -> Result<Span<'a>, ReadError> {
    let a = accessor.index();
    if accessor.sparse().is_some() {
        return Err(err(format!(
            "accessors[{a}]: sparse accessors are not supported"
        )));
    }
    let view = accessor
        .view()
        .ok_or_else(|| err(format!("accessors[{a}]: no bufferView (not supported)")))?;
    let elem = component_size * components;
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(err(format!(
            "accessors[{a}]: byteStride {stride} is smaller than the element size {elem}"
        )));
    }
    let buffer: &'a [u8] = buffers[view.buffer().index()];
    let v = view.index();
    let view_end = view
        .offset()
        .checked_add(view.length())
        .filter(|&end| end <= buffer.len())
        .ok_or_else(|| {
            err(format!(
                "bufferViews[{v}]: offset {} + length {} exceeds buffer {} of {} bytes",
                view.offset(),
                view.length(),
                view.buffer().index(),
                buffer.len()
            ))
        })?;
    let view_data = &buffer[view.offset()..view_end];
    let count = accessor.count();
    let needed = if count == 0 {
        Some(0)
    } else {
        (count - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(elem))
            .and_then(|x| x.checked_add(accessor.offset()))
    };
    match needed {
        Some(n) if n <= view_data.len() => Ok(Span {
            data: &view_data[accessor.offset().min(view_data.len())..],
            stride,
            count,
        }),
        _ => Err(err(format!(
            "accessors[{a}]: {count} elements of {elem} bytes (stride {stride}, offset {}) do not fit in bufferViews[{v}] of {} bytes",
            accessor.offset(),
            view_data.len()
        ))),
    }
}

fn read_positions(
    accessor: &gltf::Accessor,
    buffers: &[&[u8]],
) -> Result<Vec<[f32; 3]>, ReadError> {
    use gltf::accessor::{DataType, Dimensions};
    let a = accessor.index();
    if accessor.data_type() != DataType::F32 || accessor.dimensions() != Dimensions::Vec3 {
        return Err(err(format!(
            "accessors[{a}]: POSITION must be VEC3 of FLOAT (quantized positions are not supported)"
        )));
    }
    let s = span(accessor, buffers, 4, 3)?;
    let mut out = Vec::with_capacity(s.count);
    for i in 0..s.count {
        let o = i * s.stride;
        let f = |k: usize| {
            let b = &s.data[o + 4 * k..o + 4 * k + 4];
            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
        };
        let p = [f(0), f(1), f(2)];
        if !p.iter().all(|c| c.is_finite()) {
            return Err(err(format!(
                "accessors[{a}]: element {i} has a non-finite coordinate"
            )));
        }
        out.push(p);
    }
    Ok(out)
}

/// TEXCOORD_0 of a primitive with `nverts` vertices, v flipped back (glTF's origin is the top
/// left). FLOAT, or normalised UNSIGNED_BYTE / UNSIGNED_SHORT as the specification allows.
fn read_texcoords(
    accessor: &gltf::Accessor,
    buffers: &[&[u8]],
    nverts: usize,
    limits: &super::Limits,
    already: usize,
) -> Result<Vec<[f64; 2]>, String> {
    use gltf::accessor::{DataType, Dimensions};
    let a = accessor.index();
    if accessor.dimensions() != Dimensions::Vec2 {
        return Err(format!("accessors[{a}]: TEXCOORD_0 must be VEC2"));
    }
    if accessor.count() != nverts {
        return Err(format!(
            "accessors[{a}]: TEXCOORD_0 has {} elements for {nverts} vertices",
            accessor.count()
        ));
    }
    if already + accessor.count() > limits.max_triangles {
        return Err(format!(
            "more than {} texture coordinates in all",
            limits.max_triangles
        ));
    }
    let (size, norm) = match accessor.data_type() {
        DataType::F32 => (4, 1.0),
        DataType::U8 if accessor.normalized() => (1, 255.0),
        DataType::U16 if accessor.normalized() => (2, 65535.0),
        other => {
            return Err(format!(
                "accessors[{a}]: TEXCOORD_0 of {other:?} is not FLOAT or a normalised integer"
            ))
        }
    };
    let s = span(accessor, buffers, size, 2).map_err(|e| e.to_string())?;
    let mut out = Vec::with_capacity(s.count);
    for i in 0..s.count {
        let o = i * s.stride;
        let c = |k: usize| -> f64 {
            let b = &s.data[o + size * k..];
            match size {
                4 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                2 => f64::from(u16::from_le_bytes([b[0], b[1]])) / norm,
                _ => f64::from(b[0]) / norm,
            }
        };
        let (u, v) = (c(0), c(1));
        if !(u.is_finite() && v.is_finite()) {
            return Err(format!("accessors[{a}]: element {i} is not finite"));
        }
        out.push([u, 1.0 - v]);
    }
    Ok(out)
}

fn read_indices(accessor: &gltf::Accessor, buffers: &[&[u8]]) -> Result<Vec<u32>, ReadError> {
    use gltf::accessor::{DataType, Dimensions};
    let a = accessor.index();
    let size = match accessor.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        DataType::U32 => 4,
        other => {
            return Err(err(format!(
                "accessors[{a}]: indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT, not {other:?}"
            )))
        }
    };
    if accessor.dimensions() != Dimensions::Scalar {
        return Err(err(format!("accessors[{a}]: indices must be SCALAR")));
    }
    let s = span(accessor, buffers, size, 1)?;
    let mut out = Vec::with_capacity(s.count);
    for i in 0..s.count {
        let b = &s.data[i * s.stride..];
        out.push(match size {
            1 => u32::from(b[0]),
            2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
            _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        });
    }
    Ok(out)
}

type Mat4 = [[f64; 4]; 4];

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    // Column-major: (a·b)[c][r] = Σ_k a[k][r] b[c][k].
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, x) in col.iter_mut().enumerate() {
            *x = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

fn transform_point(m: &Mat4, p: [f32; 3]) -> [f64; 3] {
    let p = [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])];
    let mut out = [0.0; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r];
    }
    out
}

fn det3(m: &Mat4) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2])
        - m[1][0] * (m[0][1] * m[2][2] - m[2][1] * m[0][2])
        + m[2][0] * (m[0][1] * m[1][2] - m[1][1] * m[0][2])
}

/// A triangle primitive placed in the scene.
struct Instance<'a> {
    node: usize,
    world: Mat4,
    mesh: gltf::Mesh<'a>,
}

/// Nodes of the default scene (else the first scene, else every root node) with world
/// matrices. glTF requires the node hierarchy to be a forest; a node reached twice (a cycle or
/// two parents) is refused rather than followed.
fn scene_instances(doc: &gltf::Document) -> Result<Vec<Instance<'_>>, ReadError> {
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    let identity: Mat4 = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let mut seen = vec![false; doc.nodes().len()];
    let mut stack: Vec<(gltf::Node, Mat4)> =
        roots.into_iter().rev().map(|n| (n, identity)).collect();
    let mut out = Vec::new();
    while let Some((node, parent)) = stack.pop() {
        let i = node.index();
        if std::mem::replace(&mut seen[i], true) {
            return Err(err(format!(
                "nodes[{i}] is reached twice in the scene graph (glTF requires a tree)"
            )));
        }
        let local = node.transform().matrix().map(|c| c.map(f64::from));
        let world = mat_mul(&parent, &local);
        if !world.iter().flatten().all(|x| x.is_finite()) {
            return Err(err(format!("nodes[{i}]: transform is not finite")));
        }
        if let Some(mesh) = node.mesh() {
            out.push(Instance {
                node: i,
                world,
                mesh,
            });
        }
        let children: Vec<gltf::Node> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world));
        }
    }
    Ok(out)
}

fn patch_name(mesh: &gltf::Mesh, prim: &gltf::Primitive) -> String {
    if let Some(raw) = prim.extras() {
        if let Ok(serde_json::Value::Object(map)) = serde_json::from_str(raw.get()) {
            if let Some(serde_json::Value::String(s)) = map.get("patch") {
                return s.clone();
            }
        }
    }
    let base = mesh
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("mesh{}", mesh.index()));
    if mesh.primitives().len() == 1 {
        return base;
    }
    match prim.material().name() {
        Some(m) => format!("{base}/{m}"),
        None => format!("{base}/{}", prim.index()),
    }
}

fn assemble(
    doc: &gltf::Gltf,
    buffers: &[&[u8]],
    limits: &super::Limits,
) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    let mut warnings = Vec::new();
    let mut names_cut = 0usize;
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut space_of_vertex: Vec<u32> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut face_patch: Vec<u32> = Vec::new();
    let mut patch_names: Vec<String> = Vec::new();
    let mut name_count: HashMap<String, usize> = HashMap::new();
    // (node, POSITION accessor) → first vertex of that space.
    let mut spaces: HashMap<(usize, usize), (u32, usize)> = HashMap::new();
    let mut num_spaces = 0u32;
    let mut skipped_seen: std::collections::HashSet<(usize, usize)> = Default::default();
    // Texture coordinates: per corner, into `uv_coords`; each TEXCOORD_0 accessor read once.
    let mut uv_coords: Vec<[f64; 2]> = Vec::new();
    let mut uv_tris: Vec<Option<[u32; 3]>> = Vec::new();
    let mut uv_read: HashMap<usize, u32> = HashMap::new();
    let mut uv_problem: Option<String> = None;
    // `_VERTEX_ID` of every vertex, when every primitive has one (written by flatmesh).
    let mut vertex_ids: Option<Vec<f32>> = Some(Vec::new());

    for inst in scene_instances(doc)? {
        let flip = det3(&inst.world) < 0.0;
        for prim in inst.mesh.primitives() {
            let where_ = format!("meshes[{}].primitives[{}]", inst.mesh.index(), prim.index());
            // Skipped primitives are named once per mesh, however often it is instanced.
            let first_sight = skipped_seen.insert((inst.mesh.index(), prim.index()));
            if prim.mode() != gltf::mesh::Mode::Triangles {
                if first_sight {
                    warnings.push(Warning::new(
                        "primitive_skipped",
                        format!("{where_}: mode {:?} is not TRIANGLES; skipped", prim.mode()),
                    ));
                }
                continue;
            }
            let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
                if first_sight {
                    warnings.push(Warning::new(
                        "primitive_skipped",
                        format!("{where_}: no POSITION attribute; skipped"),
                    ));
                }
                continue;
            };
            let indexed = prim.indices();
            // Vertices of this primitive's space, and the local → global map.
            let (base, nverts, corners): (u32, usize, Vec<u32>) = match &indexed {
                Some(idx_acc) => {
                    let key = (inst.node, pos_acc.index());
                    let (base, n) = match spaces.get(&key) {
                        Some(&v) => v,
                        None => {
                            let local = read_positions(&pos_acc, buffers)?;
                            read_vertex_ids(&prim, buffers, local.len(), &mut vertex_ids);
                            if vertex_ids.is_none() {
                                warn_split_vertices(&local, &where_, &mut warnings);
                            }
                            let base = positions.len() as u32;
                            positions
                                .extend(local.iter().map(|&p| transform_point(&inst.world, p)));
                            space_of_vertex.extend(std::iter::repeat_n(num_spaces, local.len()));
                            num_spaces += 1;
                            spaces.insert(key, (base, local.len()));
                            (base, local.len())
                        }
                    };
                    (base, n, read_indices(idx_acc, buffers)?)
                }
                None => {
                    // Non-indexed: join bit-identical corners within the primitive.
                    vertex_ids = None;
                    let local = read_positions(&pos_acc, buffers)?;
                    let base = positions.len() as u32;
                    let mut index_of: HashMap<[u32; 3], u32> = HashMap::new();
                    let mut corners = Vec::with_capacity(local.len());
                    for p in &local {
                        let key = p.map(f32::to_bits);
                        let next = index_of.len() as u32;
                        let id = *index_of.entry(key).or_insert_with(|| {
                            positions.push(transform_point(&inst.world, *p));
                            space_of_vertex.push(num_spaces);
                            next
                        });
                        corners.push(id);
                    }
                    num_spaces += 1;
                    (base, index_of.len(), corners)
                }
            };
            if corners.len() % 3 != 0 {
                return Err(err(format!(
                    "{where_}: {} indices is not a multiple of 3",
                    corners.len()
                )));
            }
            if triangles.len() + corners.len() / 3 > limits.max_triangles {
                return Err(ReadError::TooLarge {
                    what: format!("triangles up to {where_}"),
                    limit: limits.max_triangles,
                });
            }
            if corners.is_empty() {
                continue;
            }
            let full = patch_name(&inst.mesh, &prim);
            let (kept, cut) = super::cap_name(&full);
            names_cut += usize::from(cut);
            let mut name = kept.to_string();
            let count = name_count.entry(name.clone()).or_insert(0);
            *count += 1;
            if *count > 1 {
                name = format!("{name}#{count}");
            }
            let patch = patch_names.len() as u32;
            patch_names.push(name);
            let uv_base = match prim.get(&gltf::Semantic::TexCoords(0)) {
                None => None,
                // Non-indexed corners were joined by position above, so their coordinates
                // (one per corner) no longer line up: not read.
                Some(_) if indexed.is_none() => {
                    uv_problem.get_or_insert(format!(
                        "{where_}: texture coordinates of a non-indexed primitive are not read"
                    ));
                    None
                }
                Some(acc) if acc.count() != nverts => {
                    uv_problem.get_or_insert(format!(
                        "{where_}: TEXCOORD_0 has {} elements for {nverts} vertices",
                        acc.count()
                    ));
                    None
                }
                Some(acc) => match uv_read.get(&acc.index()) {
                    Some(&b) => Some((b, acc.count())),
                    None => match read_texcoords(&acc, buffers, nverts, limits, uv_coords.len()) {
                        Ok(c) => {
                            let b = uv_coords.len() as u32;
                            uv_coords.extend(c);
                            uv_read.insert(acc.index(), b);
                            Some((b, acc.count()))
                        }
                        Err(why) => {
                            uv_problem.get_or_insert(format!("{where_}: {why}"));
                            None
                        }
                    },
                },
            };
            for (t, c) in corners.chunks_exact(3).enumerate() {
                if let Some(&bad) = c.iter().find(|&&i| i as usize >= nverts) {
                    return Err(err(format!(
                        "{where_}: triangle {t} uses vertex {bad} but the primitive has {nverts} vertices"
                    )));
                }
                let tri = if flip {
                    [base + c[0], base + c[2], base + c[1]]
                } else {
                    [base + c[0], base + c[1], base + c[2]]
                };
                triangles.push(tri);
                face_patch.push(patch);
                uv_tris.push(uv_base.map(|(b, _)| {
                    if flip {
                        [b + c[0], b + c[2], b + c[1]]
                    } else {
                        [b + c[0], b + c[1], b + c[2]]
                    }
                }));
            }
        }
    }
    if triangles.is_empty() {
        return Err(err("the default scene has no triangle primitive"));
    }
    if names_cut > 0 {
        warnings.push(Warning::new(
            "names_shortened",
            format!(
                "{names_cut} patch names were longer than {} bytes and were cut",
                super::MAX_NAME_BYTES
            ),
        ));
    }
    let with_uv = uv_tris.iter().filter(|t| t.is_some()).count();
    let uv = if with_uv == uv_tris.len() {
        Some(crate::mesh::UvLayer {
            coords: uv_coords,
            triangles: uv_tris.into_iter().flatten().collect(),
        })
    } else {
        if with_uv > 0 || uv_problem.is_some() {
            warnings.push(Warning::new(
                "texture_coordinates_ignored",
                match uv_problem {
                    Some(why) => format!("texture coordinates ignored: {why}"),
                    None => format!(
                        "only {with_uv} of {} triangles have texture coordinates (TEXCOORD_0); they were ignored",
                        uv_tris.len()
                    ),
                },
            ));
        }
        None
    };
    let (positions, triangles) = match vertex_ids.and_then(|ids| by_vertex_id(&positions, &ids)) {
        Some(new_index) => {
            let mut joined =
                vec![[0.0; 3]; new_index.iter().map(|&i| i as usize + 1).max().unwrap_or(0)];
            for (v, &i) in new_index.iter().enumerate() {
                joined[i as usize] = positions[v];
            }
            let triangles = triangles
                .into_iter()
                .map(|t| t.map(|v| new_index[v as usize]))
                .collect();
            (joined, triangles)
        }
        None => weld_spaces(positions, &space_of_vertex, triangles, &mut warnings),
    };
    Ok((
        RawMesh {
            positions,
            triangles,
            face_patch,
            patch_names,
            uv,
        },
        warnings,
    ))
}

/// Append the primitive's `_VERTEX_ID` values (count `n`) to `ids`, or set `ids` to None when
/// it has none or they cannot be read.
fn read_vertex_ids(
    prim: &gltf::Primitive,
    buffers: &[&[u8]],
    n: usize,
    ids: &mut Option<Vec<f32>>,
) {
    use gltf::accessor::{DataType, Dimensions};
    let Some(list) = ids.as_mut() else {
        return;
    };
    let acc = prim.attributes().find_map(|(sem, acc)| match sem {
        gltf::Semantic::Extras(name) if format!("_{name}") == VERTEX_ID => Some(acc),
        _ => None,
    });
    let read = acc.filter(|a| {
        a.count() == n && a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Scalar
    });
    match read.and_then(|a| span(&a, buffers, 4, 1).ok()) {
        Some(sp) => list.extend((0..sp.count).map(|i| {
            let b = &sp.data[i * sp.stride..];
            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
        })),
        None => *ids = None,
    }
}

/// The vertex each vertex becomes when copies with the same `_VERTEX_ID` are joined: the
/// ids' order (the written mesh's numbering, less vertices no triangle used), when the ids
/// are whole numbers and copies sit at the same position. None otherwise (the file is then
/// read as any other).
fn by_vertex_id(positions: &[[f64; 3]], ids: &[f32]) -> Option<Vec<u32>> {
    if ids.len() != positions.len() || ids.is_empty() {
        return None;
    }
    let mut first: HashMap<u32, [f64; 3]> = HashMap::with_capacity(ids.len());
    for (&id, p) in ids.iter().zip(positions) {
        if !(id >= 0.0 && id.fract() == 0.0 && id < 16_777_216.0) {
            return None;
        }
        match first.entry(id as u32) {
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(*p);
            }
            std::collections::hash_map::Entry::Occupied(e) if e.get() == p => {}
            std::collections::hash_map::Entry::Occupied(_) => return None,
        }
    }
    let mut distinct: Vec<u32> = first.into_keys().collect();
    distinct.sort_unstable();
    let rank: HashMap<u32, u32> = distinct
        .iter()
        .enumerate()
        .map(|(k, &id)| (id, k as u32))
        .collect();
    Some(ids.iter().map(|&id| rank[&(id as u32)]).collect())
}

/// Exporters split a vertex where its normal or texture coordinate changes (flat shading, UV
/// seams). Those splits are kept, because an indexed file's connectivity is its own and a cut
/// looks the same, but the user is told, since they open the surface along the split.
fn warn_split_vertices(local: &[[f32; 3]], where_: &str, warnings: &mut Vec<Warning>) {
    let mut seen: HashMap<[u32; 3], ()> = HashMap::with_capacity(local.len());
    let duplicates = local
        .iter()
        .filter(|p| seen.insert(p.map(f32::to_bits), ()).is_some())
        .count();
    if duplicates > 0 {
        warnings.push(Warning::new(
            "coincident_vertices_kept",
            format!(
                "{where_}: {duplicates} vertices coincide with another vertex of the same accessor (split for normals or texture coordinates?); they are kept apart, which opens the surface there: export with merged vertices, or as OBJ, to measure it as one surface"
            ),
        ));
    }
}

/// Weld border vertices of different spaces that coincide within [`WELD_RELATIVE`] × the
/// bounding-box diagonal; the survivor is the vertex that came first. Vertex order is kept
/// otherwise.
fn weld_spaces(
    positions: Vec<[f64; 3]>,
    space: &[u32],
    mut triangles: Vec<[u32; 3]>,
    warnings: &mut Vec<Warning>,
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let n = positions.len();
    if space.iter().all(|&s| s == space[0]) {
        return (positions, triangles);
    }
    // Border vertices: on an edge used by exactly one triangle of its own space (edges never
    // cross spaces before welding).
    let mut edge_use: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 3 / 2);
    for t in &triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *edge_use.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let mut border = vec![false; n];
    for (&(a, b), &k) in &edge_use {
        if k == 1 {
            border[a as usize] = true;
            border[b as usize] = true;
        }
    }
    let (lo, hi) = crate::mesh::bbox_of(positions.iter().copied());
    let diag = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let tol = WELD_RELATIVE * diag;
    if tol <= 0.0 {
        return (positions, triangles);
    }
    let cell = |p: [f64; 3]| -> [i64; 3] { p.map(|x| (x / tol).floor() as i64) };
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut target: Vec<u32> = (0..n as u32).collect();
    let mut welded = 0usize;
    for v in 0..n {
        if !border[v] {
            continue;
        }
        let p = positions[v];
        let c = cell(p);
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &w in list {
                            let q = positions[w as usize];
                            let d2 = (p[0] - q[0]).powi(2)
                                + (p[1] - q[1]).powi(2)
                                + (p[2] - q[2]).powi(2);
                            if space[w as usize] != space[v] && d2 <= tol * tol {
                                found = Some(w);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        match found {
            Some(w) => {
                target[v] = w;
                welded += 1;
            }
            None => grid.entry(c).or_default().push(v as u32),
        }
    }
    if welded == 0 {
        return (positions, triangles);
    }
    // Compact: survivors keep their relative order.
    let mut new_index = vec![u32::MAX; n];
    let mut kept = Vec::with_capacity(n - welded);
    for v in 0..n {
        if target[v] as usize == v {
            new_index[v] = kept.len() as u32;
            kept.push(positions[v]);
        }
    }
    for t in &mut triangles {
        for i in t.iter_mut() {
            *i = new_index[target[*i as usize] as usize];
        }
    }
    warnings.push(Warning::new(
        "vertices_welded",
        format!(
            "{welded} border vertices of different primitives welded (tolerance {tol:.3e}, {WELD_RELATIVE:e} of the bounding-box diagonal)"
        ),
    ));
    (kept, triangles)
}

/// How the heat map's range is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HeatmapScale {
    /// From the data: the 1st to the 99th percentile of ϖ at interior vertices (at least a
    /// decade wide, never below [`HEATMAP_MIN`]), so that a typical garment, whose ϖ spans
    /// 1e-3–0.3 rad, is not shown in one colour.
    #[default]
    Data,
    /// [`HEATMAP_MIN`]–[`HEATMAP_MAX`], the same for every mesh (to compare meshes).
    Fixed,
}

/// The heat map's `(min, max)` for `scale` over the interior vertices' ϖ.
pub fn heatmap_range(scale: HeatmapScale, interior: &[f64]) -> (f64, f64) {
    if scale == HeatmapScale::Fixed {
        return (HEATMAP_MIN, HEATMAP_MAX);
    }
    let mut v: Vec<f64> = interior.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (HEATMAP_MIN, HEATMAP_MIN * 10.0);
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let lo = at(0.01).max(HEATMAP_MIN);
    let hi = at(0.99).max(lo * 10.0);
    (lo, hi)
}

/// Heat-map colour of ϖ on the fixed scale (see [`heat_color_in`]).
pub fn heat_color(varpi: f64) -> [f32; 3] {
    heat_color_in(varpi, (HEATMAP_MIN, HEATMAP_MAX))
}

/// Heat-map colour of ϖ: log scale from `range.0` (blue) through cyan, green and yellow to
/// `range.1` (red).
pub fn heat_color_in(varpi: f64, range: (f64, f64)) -> [f32; 3] {
    let (lo, hi) = range;
    let t = if varpi <= lo || hi <= lo {
        0.0
    } else {
        ((varpi / lo).log10() / (hi / lo).log10()).clamp(0.0, 1.0)
    };
    const STOPS: [[f64; 3]; 5] = [
        [0.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
    ];
    let x = t * 4.0;
    let i = (x.floor() as usize).min(3);
    let f = x - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|k| (a[k] + (b[k] - a[k]) * f) as f32)
}

/// Build the glTF JSON and the binary buffer.
/// A custom per-vertex scalar attribute (`_NAME`, f32), described in `asset.extras.flatmesh`.
#[derive(Debug, Clone, Copy)]
pub struct VertexScalar<'a> {
    /// Attribute name; glTF requires custom ones to start with `_`.
    pub attribute: &'a str,
    /// What it measures, in words (with its unit).
    pub quantity: &'a str,
    /// One value per vertex.
    pub values: &'a [f64],
}

fn build(
    mesh: &Mesh,
    flattenability: Option<&[f64]>,
    scalars: &[VertexScalar<'_>],
    scale: HeatmapScale,
) -> (serde_json::Value, Vec<u8>) {
    use serde_json::json;
    let n = mesh.num_vertices();
    let conn = mesh.conn();
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    // Every view starts 4-aligned; every accessor is 4-byte components.
    let mut push_view = |bin: &mut Vec<u8>, data: &[u8], target: u32| -> usize {
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len(), "target": target}));
        bin.extend_from_slice(data);
        views.len() - 1
    };

    // Heat map range and colours over the whole mesh.
    let mut range = (HEATMAP_MIN, HEATMAP_MAX);
    let varpi32: Option<Vec<f32>> = flattenability.map(|varpi| {
        (0..n)
            .map(|i| varpi.get(i).copied().unwrap_or(0.0))
            .map(|x| if x.is_finite() { x as f32 } else { 0.0 })
            .collect()
    });
    let colors: Option<Vec<[f32; 3]>> = flattenability.map(|varpi| {
        let interior: Vec<f64> = (0..n)
            .filter(|&i| conn.is_interior(i as u32))
            .map(|i| varpi.get(i).copied().unwrap_or(0.0))
            .collect();
        range = heatmap_range(scale, &interior);
        (0..n)
            .map(|i| {
                if conn.is_interior(i as u32) {
                    heat_color_in(varpi.get(i).copied().unwrap_or(0.0), range)
                } else {
                    NON_INTERIOR_COLOR
                }
            })
            .collect()
    });
    let scalars32: Vec<Vec<f32>> = scalars
        .iter()
        .map(|sc| {
            (0..n)
                .map(|i| sc.values.get(i).copied().unwrap_or(0.0))
                .map(|x| if x.is_finite() { x as f32 } else { 0.0 })
                .collect()
        })
        .collect();
    // NORMAL: angle-weighted vertex normals; unit length is required, so vertices without a
    // normal (unreferenced) get +Z.
    let normals: Vec<[f32; 3]> = geometry::vertex_normals(mesh)
        .into_iter()
        .map(|nrm| {
            let l = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
            if l.is_finite() && l > 0.5 {
                let u = [nrm[0] / l, nrm[1] / l, nrm[2] / l].map(|x| x as f32);
                // Renormalise in f32 so the stored vector is unit to f32 precision.
                let l32 = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                u.map(|x| x / l32)
            } else {
                [0.0, 0.0, 1.0]
            }
        })
        .collect();
    let pos32: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| p.map(|x| x as f32))
        .collect();

    let mut primitives = Vec::new();
    let sets = vertex_sets(mesh);
    // Any layout but the shared one renumbers vertices: say which mesh vertex each one is.
    let split = !(sets.len() == 1
        && sets[0].vertices.len() == n
        && sets[0]
            .vertices
            .iter()
            .enumerate()
            .all(|(i, &v)| v as usize == i));
    for set in sets {
        let m = set.vertices.len();
        let per_vertex = |f: &dyn Fn(usize) -> f32| -> Vec<u8> {
            set.vertices
                .iter()
                .flat_map(|&v| f(v as usize).to_le_bytes())
                .collect()
        };
        // POSITION, with min/max of the f32 values actually stored.
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        let mut bytes = Vec::with_capacity(12 * m);
        for &v in &set.vertices {
            let p = pos32[v as usize];
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
                bytes.extend_from_slice(&p[k].to_le_bytes());
            }
        }
        let view = push_view(&mut bin, &bytes, 34962);
        accessors.push(
            json!({"bufferView": view, "componentType": 5126, "count": m,
            "type": "VEC3", "min": min, "max": max}),
        );
        let mut attributes = json!({"POSITION": accessors.len() - 1});
        let vec3 = |data: &[[f32; 3]]| -> Vec<u8> {
            set.vertices
                .iter()
                .flat_map(|&v| data[v as usize])
                .flat_map(f32::to_le_bytes)
                .collect()
        };
        let view = push_view(&mut bin, &vec3(&normals), 34962);
        accessors
            .push(json!({"bufferView": view, "componentType": 5126, "count": m, "type": "VEC3"}));
        attributes["NORMAL"] = json!(accessors.len() - 1);
        if let (Some(values), Some(colors)) = (&varpi32, &colors) {
            let view = push_view(&mut bin, &per_vertex(&|v| values[v]), 34962);
            accessors.push(
                json!({"bufferView": view, "componentType": 5126, "count": m, "type": "SCALAR"}),
            );
            attributes["_FLATTENABILITY"] = json!(accessors.len() - 1);
            let view = push_view(&mut bin, &vec3(colors), 34962);
            accessors.push(
                json!({"bufferView": view, "componentType": 5126, "count": m, "type": "VEC3"}),
            );
            attributes["COLOR_0"] = json!(accessors.len() - 1);
        }
        for (sc, values) in scalars.iter().zip(&scalars32) {
            let view = push_view(&mut bin, &per_vertex(&|v| values[v]), 34962);
            accessors.push(
                json!({"bufferView": view, "componentType": 5126, "count": m, "type": "SCALAR"}),
            );
            attributes[sc.attribute] = json!(accessors.len() - 1);
        }
        if split {
            // The mesh vertex of each written vertex (exact in f32 below 2²⁴), so that a
            // reader can join what was split for the texture coordinates.
            let ids: Vec<u8> = set
                .vertices
                .iter()
                .flat_map(|&v| (v as f32).to_le_bytes())
                .collect();
            let view = push_view(&mut bin, &ids, 34962);
            accessors.push(
                json!({"bufferView": view, "componentType": 5126, "count": m, "type": "SCALAR"}),
            );
            attributes[VERTEX_ID] = json!(accessors.len() - 1);
        }
        if let Some(uv) = &set.uv {
            // glTF's texture origin is the top left: v is stored as 1 − v.
            let bytes: Vec<u8> = uv
                .iter()
                .flat_map(|c| [c[0] as f32, (1.0 - c[1]) as f32])
                .flat_map(f32::to_le_bytes)
                .collect();
            let view = push_view(&mut bin, &bytes, 34962);
            accessors.push(
                json!({"bufferView": view, "componentType": 5126, "count": m, "type": "VEC2"}),
            );
            attributes["TEXCOORD_0"] = json!(accessors.len() - 1);
        }
        for (p, idx) in &set.patches {
            let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
            let view = push_view(&mut bin, &bytes, 34963);
            accessors.push(
                json!({"bufferView": view, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}),
            );
            primitives.push(
                json!({"attributes": attributes.clone(), "indices": accessors.len() - 1,
                "mode": 4, "material": 0, "extras": {"patch": mesh.patch_names()[*p]}}),
            );
        }
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut asset =
        json!({"version": "2.0", "generator": concat!("flatmesh ", env!("CARGO_PKG_VERSION"))});
    if flattenability.is_some() {
        asset["extras"] = json!({"flatmesh": {
            "attribute": "_FLATTENABILITY",
            "quantity": "flattenability |2π − θ| at interior vertices, radians (0 elsewhere)",
            "heatmap": {
                "attribute": "COLOR_0",
                "scale": "log10",
                "range": match scale {
                    HeatmapScale::Data => "data: 1st to 99th percentile of interior ϖ",
                    HeatmapScale::Fixed => "fixed",
                },
                "min": range.0,
                "max": range.1,
                "colors": "blue at or below min (developable), cyan, green, yellow, red at or above max",
                "non_interior": NON_INTERIOR_COLOR,
            }
        }});
    }
    for sc in scalars {
        asset["extras"]["flatmesh"]["attributes"][sc.attribute] = json!(sc.quantity);
    }
    if split {
        asset["extras"]["flatmesh"]["attributes"][VERTEX_ID] = json!(
            "the mesh vertex each vertex is a copy of (vertices are written once per texture \
             coordinate they have in their patch); flatmesh joins the copies when reading"
        );
    }
    let root = json!({
        "asset": asset,
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "flatmesh"}],
        "meshes": [{"name": "flatmesh", "primitives": primitives}],
        // Without a material, viewers use glTF's default: fully metallic and single-sided
        // (nearly black in three.js, a garment's inside culled). Vertex colours (the heat
        // map) multiply the white base colour.
        "materials": [{
            "name": "flatmesh",
            "pbrMetallicRoughness": {
                "baseColorFactor": if flattenability.is_some() { [1.0, 1.0, 1.0, 1.0] } else { [0.8, 0.8, 0.8, 1.0] },
                "metallicFactor": 0.0,
                "roughnessFactor": 0.8,
            },
            "doubleSided": true,
        }],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    (root, bin)
}

/// The vertices written and the primitives that index them.
struct VertexSet {
    /// Mesh vertex of each written vertex.
    vertices: Vec<u32>,
    /// Texture coordinate of each written vertex.
    uv: Option<Vec<[f64; 2]>>,
    /// (patch, indices into `vertices`), one primitive each.
    patches: Vec<(usize, Vec<u32>)>,
}

/// Without texture coordinates, or with one per vertex, one set of every mesh vertex in mesh
/// order, shared by one primitive per patch (a file reads back with the same numbering).
/// Otherwise one set per patch, a vertex written once per texture coordinate it has there:
/// glTF has one texture coordinate per vertex, and the reader welds the patches back along
/// their seams.
fn vertex_sets(mesh: &Mesh) -> Vec<VertexSet> {
    let mut by_patch: Vec<Vec<usize>> = vec![Vec::new(); mesh.num_patches()];
    for (f, &p) in mesh.face_patch().iter().enumerate() {
        by_patch[p as usize].push(f);
    }
    // Every mesh vertex in mesh order, one primitive per patch.
    let shared = |uv: Option<Vec<[f64; 2]>>| VertexSet {
        vertices: (0..mesh.num_vertices() as u32).collect(),
        uv,
        patches: by_patch
            .iter()
            .enumerate()
            .filter(|(_, fs)| !fs.is_empty())
            .map(|(p, fs)| (p, fs.iter().flat_map(|&f| mesh.triangles()[f]).collect()))
            .collect(),
    };
    let Some(uv) = mesh.uv() else {
        return vec![shared(None)];
    };
    // Every vertex with one texture coordinate (by value): the shared layout still fits.
    let mut per_vertex: Vec<Option<[f64; 2]>> = vec![None; mesh.num_vertices()];
    let mut single = true;
    for (t, ut) in mesh.triangles().iter().zip(&uv.triangles) {
        for k in 0..3 {
            let c = uv.coords[ut[k] as usize];
            match per_vertex[t[k] as usize] {
                None => per_vertex[t[k] as usize] = Some(c),
                Some(d) => single &= d == c,
            }
        }
    }
    if single {
        return vec![shared(Some(
            per_vertex.iter().map(|c| c.unwrap_or([0.0; 2])).collect(),
        ))];
    }
    let mut sets = Vec::new();
    for (p, faces) in by_patch.iter().enumerate() {
        if faces.is_empty() {
            continue;
        }
        let mut index: HashMap<(u32, u32), u32> = HashMap::new();
        let mut set = VertexSet {
            vertices: Vec::new(),
            uv: Some(Vec::new()),
            patches: vec![(p, Vec::with_capacity(3 * faces.len()))],
        };
        for &f in faces {
            for k in 0..3 {
                let key = (mesh.triangles()[f][k], uv.triangles[f][k]);
                let next = set.vertices.len() as u32;
                let i = *index.entry(key).or_insert_with(|| {
                    set.vertices.push(key.0);
                    if let Some(c) = set.uv.as_mut() {
                        c.push(uv.coords[key.1 as usize]);
                    }
                    next
                });
                set.patches[0].1.push(i);
            }
        }
        sets.push(set);
    }
    // Vertices no triangle uses still go into the file (in the first set), so that joining
    // the copies by `_VERTEX_ID` gives back the mesh's own numbering.
    let mut used = vec![false; mesh.num_vertices()];
    for t in mesh.triangles() {
        for &v in t {
            used[v as usize] = true;
        }
    }
    if let Some(first) = sets.first_mut() {
        for (v, _) in used.iter().enumerate().filter(|(_, u)| !**u) {
            first.vertices.push(v as u32);
            if let Some(c) = first.uv.as_mut() {
                c.push([0.0, 0.0]);
            }
        }
    }
    sets
}

/// Binary glTF: POSITION, NORMAL, one indexed primitive per patch (patch name in the
/// primitive's extras) and, when `flattenability` is given, `_FLATTENABILITY` and a COLOR_0
/// heat map whose scale is stated in `asset.extras.flatmesh`.
pub fn write_glb(mesh: &Mesh, flattenability: Option<&[f64]>) -> Vec<u8> {
    write_glb_with(mesh, flattenability, &[])
}

/// [`write_glb`] with further per-vertex scalar attributes.
pub fn write_glb_with(
    mesh: &Mesh,
    flattenability: Option<&[f64]>,
    scalars: &[VertexScalar<'_>],
) -> Vec<u8> {
    write_glb_scaled(mesh, flattenability, scalars, HeatmapScale::Data)
}

/// [`write_glb_with`] with the heat map's range chosen by `scale`.
pub fn write_glb_scaled(
    mesh: &Mesh,
    flattenability: Option<&[f64]>,
    scalars: &[VertexScalar<'_>],
    scale: HeatmapScale,
) -> Vec<u8> {
    let (root, bin) = build(mesh, flattenability, scalars, scale);
    let mut json = serde_json::to_vec(&root).unwrap_or_default();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// `.gltf` JSON with the buffer embedded as a base64 `data:` URI; same content as
/// [`write_glb`].
pub fn write_gltf(mesh: &Mesh, flattenability: Option<&[f64]>) -> Vec<u8> {
    write_gltf_with(mesh, flattenability, &[])
}

/// [`write_gltf`] with further per-vertex scalar attributes.
pub fn write_gltf_with(
    mesh: &Mesh,
    flattenability: Option<&[f64]>,
    scalars: &[VertexScalar<'_>],
) -> Vec<u8> {
    let (mut root, bin) = build(mesh, flattenability, scalars, HeatmapScale::Data);
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    root["buffers"][0]["uri"] = serde_json::Value::String(uri);
    serde_json::to_vec_pretty(&root).unwrap_or_default()
}
