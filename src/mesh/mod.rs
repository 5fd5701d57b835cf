//! The one mesh type: f64 positions, u32 triangles, a patch id per face.
//!
//! A [`Mesh`] is only ever built through [`Mesh::new`], which validates the input and builds
//! the [`Connectivity`] once. Connectivity is immutable and shared (`Arc`) between meshes that
//! differ only in vertex positions ([`Mesh::with_positions`]), which is what every optimiser
//! produces.
//!
//! What is fatal and what is repaired (a user's vertex indices are never renumbered, so that
//! reports can be matched to the file):
//!
//! | problem | decision |
//! |---|---|
//! | no faces | fatal [`MeshError::Empty`] |
//! | index out of range | fatal, names face and corner |
//! | NaN/∞ coordinate | fatal, names vertex and axis |
//! | triangle with a repeated index or zero area | fatal, names the face |
//! | edge with more than two faces | fatal, names the edge and its faces |
//! | vertex with more than one fan (bow-tie) | repaired: each fan after the first gets a new vertex at the same position (numbered after the file's), with a warning naming them |
//! | duplicate face (same three vertices) | fatal, names both faces |
//! | inconsistent orientation, orientable component | repaired: the minority of the component's faces is flipped, with a warning naming them |
//! | non-orientable component | fatal, names an edge where orientation cannot agree |
//! | unreferenced vertex | kept (indices stay the file's) but ignored by every measure, with a warning |

mod connectivity;
pub mod disjoint;
pub mod islands;

pub use connectivity::{Connectivity, PatchTopology, VertexKind, NONE};

use serde::Serialize;
use std::sync::Arc;

/// Index of a vertex.
pub type VertexId = u32;
/// Index of a triangle.
pub type FaceId = u32;

/// A triangle counts as degenerate when twice its area is at most this fraction of its
/// longest edge squared, i.e. its smallest angle is below about 1e-12 rad: below that, angles
/// and their gradients lose all precision.
pub const DEGENERATE_REL_AREA: f64 = 1e-12;

/// Mesh data as a reader produces it, before validation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RawMesh {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// Patch id of each triangle (index into `patch_names`).
    pub face_patch: Vec<u32>,
    /// Patch names; at least one when there are faces.
    pub patch_names: Vec<String>,
    /// Optional texture coordinates, kept so that a file's own flat pattern (OBJ `vt`) can be
    /// compared with ours.
    pub uv: Option<UvLayer>,
}

/// Texture coordinates indexed per triangle corner (OBJ `vt`, glTF TEXCOORD_0).
#[derive(Debug, Clone, PartialEq)]
pub struct UvLayer {
    /// The coordinates.
    pub coords: Vec<[f64; 2]>,
    /// For each triangle, the index into `coords` of each corner.
    pub triangles: Vec<[u32; 3]>,
}

/// Something repaired or ignored on the way in; carried into every report.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Warning {
    /// Stable machine-readable code, e.g. `unreferenced_vertices`.
    pub code: &'static str,
    /// Human-readable detail naming the elements concerned.
    pub message: String,
}

impl Warning {
    /// A warning with the given code and message.
    pub fn new(code: &'static str, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }
}

/// Why a mesh was refused. Every variant names the element at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// The mesh has no triangles.
    #[error("the mesh has no faces")]
    Empty,
    /// Array lengths disagree (a reader bug or malformed input).
    #[error("{what}")]
    Inconsistent {
        /// What disagrees.
        what: String,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("face {face} corner {corner} refers to vertex {index}, but there are only {vertices} vertices")]
    IndexOutOfRange {
        /// Face index.
        face: usize,
        /// Corner 0..3.
        corner: usize,
        /// The offending index.
        index: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// A triangle's patch id is not a known patch.
    #[error("face {face} has patch id {patch}, but there are only {patches} patches")]
    PatchOutOfRange {
        /// Face index.
        face: usize,
        /// The offending patch id.
        patch: u32,
        /// Number of patches.
        patches: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite {axis} coordinate ({value})")]
    NonFinite {
        /// Vertex index.
        vertex: usize,
        /// `x`, `y` or `z`.
        axis: char,
        /// The value.
        value: f64,
    },
    /// A coordinate too large to measure or to write (glTF stores f32).
    #[error(
        "vertex {vertex} has {axis} = {value:e}, beyond ±{MAX_COORDINATE:e}: lengths could \
         not be measured in f64 nor written to glTF (f32); rescale the mesh"
    )]
    OutOfRange {
        /// Vertex index.
        vertex: usize,
        /// `x`, `y` or `z`.
        axis: char,
        /// The value.
        value: f64,
    },
    /// The whole mesh is too small for its angles and areas to be measured.
    #[error(
        "the mesh is {diagonal:e} across (bounding-box diagonal), below {MIN_EXTENT:e}: its \
         areas and angles cannot be measured in f64; rescale it"
    )]
    TooSmall {
        /// Bounding-box diagonal.
        diagonal: f64,
    },
    /// A triangle has a repeated vertex or (numerically) zero area.
    #[error("face {face} (vertices {} {} {}) is degenerate: {reason}", .vertices[0], .vertices[1], .vertices[2])]
    DegenerateFace {
        /// Face index.
        face: usize,
        /// Its vertices.
        vertices: [u32; 3],
        /// `repeated vertex` or `zero area`.
        reason: &'static str,
    },
    /// Two faces use the same three vertices.
    #[error("face {face} duplicates face {first} (vertices {} {} {})", .vertices[0], .vertices[1], .vertices[2])]
    DuplicateFace {
        /// The later face.
        face: usize,
        /// The earlier face with the same vertices.
        first: usize,
        /// The vertices.
        vertices: [u32; 3],
    },
    /// An edge is shared by more than two faces.
    #[error("non-manifold edge {a}-{b}: shared by {} faces ({})", .faces.len(), join(.faces))]
    NonManifoldEdge {
        /// Lower vertex of the edge.
        a: u32,
        /// Higher vertex of the edge.
        b: u32,
        /// All faces on the edge.
        faces: Vec<u32>,
    },
    /// A vertex's faces form more than one fan (a bow-tie).
    #[error("non-manifold vertex {vertex}: its faces form {fans} separate fans")]
    NonManifoldVertex {
        /// Vertex index.
        vertex: u32,
        /// Number of fans.
        fans: usize,
    },
    /// A connected component cannot be consistently oriented (e.g. a Möbius strip).
    #[error("non-orientable surface: faces {f0} and {f1} cannot agree in orientation across edge {a}-{b}")]
    NonOrientable {
        /// Lower vertex of the edge.
        a: u32,
        /// Higher vertex of the edge.
        b: u32,
        /// One face.
        f0: u32,
        /// The other face.
        f1: u32,
    },
}

fn join(v: &[u32]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A validated triangle mesh with immutable connectivity.
#[derive(Debug, Clone)]
pub struct Mesh {
    positions: Vec<[f64; 3]>,
    triangles: Arc<Vec<[u32; 3]>>,
    face_patch: Arc<Vec<u32>>,
    patch_names: Arc<Vec<String>>,
    uv: Option<Arc<UvLayer>>,
    conn: Arc<Connectivity>,
}

impl Mesh {
    /// Validate `raw` and build its connectivity. Returns the mesh and what was repaired.
    pub fn new(raw: RawMesh) -> Result<(Mesh, Vec<Warning>), MeshError> {
        let RawMesh {
            mut positions,
            mut triangles,
            mut face_patch,
            mut patch_names,
            uv,
        } = raw;
        if triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        if face_patch.is_empty() {
            face_patch = vec![0; triangles.len()];
        }
        if patch_names.is_empty() {
            patch_names.push("default".to_string());
        }
        if face_patch.len() != triangles.len() {
            return Err(MeshError::Inconsistent {
                what: format!(
                    "{} patch ids for {} faces",
                    face_patch.len(),
                    triangles.len()
                ),
            });
        }
        let nv = positions.len();
        for (f, t) in triangles.iter().enumerate() {
            for (c, &i) in t.iter().enumerate() {
                if i as usize >= nv {
                    return Err(MeshError::IndexOutOfRange {
                        face: f,
                        corner: c,
                        index: i,
                        vertices: nv,
                    });
                }
            }
            let p = face_patch[f];
            if p as usize >= patch_names.len() {
                return Err(MeshError::PatchOutOfRange {
                    face: f,
                    patch: p,
                    patches: patch_names.len(),
                });
            }
        }
        if let Some(uv) = &uv {
            check_uv(uv, triangles.len())?;
        }
        check_finite(&positions)?;
        check_faces(&positions, &triangles)?;
        let mut warnings = Vec::new();
        compact_patches(&mut face_patch, &mut patch_names, &mut warnings);
        split_bow_ties(&mut positions, &mut triangles, &mut warnings);
        let nv = positions.len();
        let before = uv.as_ref().map(|_| triangles.clone());
        let conn = Connectivity::build(
            nv,
            &mut triangles,
            &face_patch,
            patch_names.len(),
            &mut warnings,
        )?;
        // A face whose orientation was repaired has its corners 1 and 2 swapped: its texture
        // corners follow.
        let mut uv = uv;
        if let (Some(uv), Some(before)) = (uv.as_mut(), before) {
            for ((t, b), u) in triangles.iter().zip(&before).zip(&mut uv.triangles) {
                if t != b {
                    u.swap(1, 2);
                }
            }
        }
        let mesh = Mesh {
            positions,
            triangles: Arc::new(triangles),
            face_patch: Arc::new(face_patch),
            patch_names: Arc::new(patch_names),
            uv: uv.map(Arc::new),
            conn: Arc::new(conn),
        };
        Ok((mesh, warnings))
    }

    /// The same mesh with new vertex positions (connectivity shared). Fails, naming the
    /// element, when a position is not finite or a face became degenerate.
    pub fn with_positions(&self, positions: Vec<[f64; 3]>) -> Result<Mesh, MeshError> {
        if positions.len() != self.positions.len() {
            return Err(MeshError::Inconsistent {
                what: format!(
                    "{} positions for a mesh of {} vertices",
                    positions.len(),
                    self.positions.len()
                ),
            });
        }
        check_finite(&positions)?;
        check_faces(&positions, &self.triangles)?;
        Ok(Mesh {
            positions,
            ..self.clone_shallow()
        })
    }

    /// The same mesh with texture coordinates (replacing any it had). Fails when the layer
    /// does not have one triangle per face, refers past its coordinates, or is not finite.
    pub fn with_uv(&self, uv: UvLayer) -> Result<Mesh, MeshError> {
        check_uv(&uv, self.triangles.len())?;
        Ok(Mesh {
            positions: self.positions.clone(),
            uv: Some(Arc::new(uv)),
            ..self.clone_shallow()
        })
    }

    fn clone_shallow(&self) -> Mesh {
        Mesh {
            positions: Vec::new(),
            triangles: self.triangles.clone(),
            face_patch: self.face_patch.clone(),
            patch_names: self.patch_names.clone(),
            uv: self.uv.clone(),
            conn: self.conn.clone(),
        }
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.positions
    }
    /// Triangles (after any orientation repair).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// Patch id of each face.
    pub fn face_patch(&self) -> &[u32] {
        &self.face_patch
    }
    /// Patch names, indexed by patch id.
    pub fn patch_names(&self) -> &[String] {
        &self.patch_names
    }
    /// Texture coordinates, when the input had them.
    pub fn uv(&self) -> Option<&UvLayer> {
        self.uv.as_deref()
    }
    /// Connectivity (built once).
    pub fn conn(&self) -> &Connectivity {
        &self.conn
    }
    /// Number of vertices (including unreferenced ones).
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }
    /// Number of triangles.
    pub fn num_faces(&self) -> usize {
        self.triangles.len()
    }
    /// Number of patches.
    pub fn num_patches(&self) -> usize {
        self.patch_names.len()
    }
    /// Position of vertex `v`.
    #[inline]
    pub fn position(&self, v: u32) -> [f64; 3] {
        self.positions[v as usize]
    }
    /// The three positions of face `f`.
    #[inline]
    pub fn face_positions(&self, f: usize) -> [[f64; 3]; 3] {
        let t = self.triangles[f];
        [
            self.positions[t[0] as usize],
            self.positions[t[1] as usize],
            self.positions[t[2] as usize],
        ]
    }
    /// Back to raw data (e.g. for writing).
    pub fn to_raw(&self) -> RawMesh {
        RawMesh {
            positions: self.positions.clone(),
            triangles: self.triangles.to_vec(),
            face_patch: self.face_patch.to_vec(),
            patch_names: self.patch_names.to_vec(),
            uv: self.uv.as_deref().cloned(),
        }
    }
    /// Axis-aligned bounding box of the referenced vertices.
    pub fn bbox(&self) -> ([f64; 3], [f64; 3]) {
        bbox_of(
            self.conn
                .referenced_vertices()
                .map(|v| self.positions[v as usize]),
        )
    }
}

/// Give each fan of a bow-tie vertex (faces around it that meet only at it, e.g. where two
/// boundary loops touch) its own vertex at the same position: the surface is the same, and
/// every algorithm needs one fan per vertex. The first fan keeps the vertex; the others get
/// new vertices numbered after the existing ones. Said in a warning.
fn split_bow_ties(
    positions: &mut Vec<[f64; 3]>,
    triangles: &mut [[u32; 3]],
    warnings: &mut Vec<Warning>,
) {
    // Corners sorted by vertex: (vertex, face, the two other vertices).
    let mut corners: Vec<(u32, u32, u32, u32)> = Vec::with_capacity(3 * triangles.len());
    for (f, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            corners.push((t[k], f as u32, t[(k + 1) % 3], t[(k + 2) % 3]));
        }
    }
    corners.sort_unstable();
    let mut split: Vec<(u32, u32)> = Vec::new();
    let (mut sets, mut via) = (
        disjoint::DisjointSets::default(),
        std::collections::HashMap::new(),
    );
    for group in corners.chunk_by(|a, b| a.0 == b.0) {
        // The vertex's faces, joined through each neighbour they share.
        sets.reset(group.len());
        via.clear();
        for (i, c) in group.iter().enumerate() {
            for w in [c.2, c.3] {
                if let Some(&j) = via.get(&w) {
                    sets.union(i as u32, j);
                } else {
                    via.insert(w, i as u32);
                }
            }
        }
        let v = group[0].0;
        let mut copy_of_root = std::collections::HashMap::new();
        for i in 0..group.len() as u32 {
            let r = sets.find(i);
            if r == 0 {
                continue;
            }
            let copy = *copy_of_root.entry(r).or_insert_with(|| {
                positions.push(positions[v as usize]);
                let copy = (positions.len() - 1) as u32;
                split.push((v, copy));
                copy
            });
            for x in triangles[group[i as usize].1 as usize].iter_mut() {
                if *x == v {
                    *x = copy;
                }
            }
        }
    }
    if !split.is_empty() {
        let mut vertices: Vec<u32> = split.iter().map(|s| s.0).collect();
        vertices.dedup();
        let shown: Vec<String> = split
            .iter()
            .take(20)
            .map(|(v, c)| format!("{v} → {v} and {c}"))
            .collect();
        warnings.push(Warning::new(
            "bow_tie_vertices_split",
            format!(
                "{} vertices where separate fans of faces met were split, one vertex per \
                 fan at the same position ({}{}); the new vertices are {} to {}, in the order \
                 of the vertices they copy",
                vertices.len(),
                shown.join(", "),
                if split.len() > 20 { ", …" } else { "" },
                split[0].1,
                split[split.len() - 1].1
            ),
        ));
    }
}

/// Drop patches that have no faces (harmless, but worth a warning) so every patch has faces.
fn compact_patches(
    face_patch: &mut [u32],
    patch_names: &mut Vec<String>,
    warnings: &mut Vec<Warning>,
) {
    let mut used = vec![false; patch_names.len()];
    for &p in face_patch.iter() {
        used[p as usize] = true;
    }
    if used.iter().all(|&u| u) {
        return;
    }
    let empty: Vec<&str> = patch_names
        .iter()
        .zip(&used)
        .filter(|(_, u)| !**u)
        .map(|(n, _)| n.as_str())
        .collect();
    warnings.push(Warning::new(
        "empty_patches",
        format!("patches with no faces were dropped: {}", empty.join(", ")),
    ));
    let mut remap = vec![u32::MAX; patch_names.len()];
    let mut names = Vec::new();
    for (i, n) in patch_names.iter().enumerate() {
        if used[i] {
            remap[i] = names.len() as u32;
            names.push(n.clone());
        }
    }
    for p in face_patch.iter_mut() {
        *p = remap[*p as usize];
    }
    *patch_names = names;
}

/// Bounding box of a set of points (`[+inf; 3], [-inf; 3]` when empty).
fn check_uv(uv: &UvLayer, faces: usize) -> Result<(), MeshError> {
    if uv.triangles.len() != faces {
        return Err(MeshError::Inconsistent {
            what: format!("{} texture triangles for {faces} faces", uv.triangles.len()),
        });
    }
    if let Some((f, _)) = uv
        .triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i as usize >= uv.coords.len()))
    {
        return Err(MeshError::Inconsistent {
            what: format!("face {f} refers to a texture coordinate that does not exist"),
        });
    }
    if let Some(k) = uv
        .coords
        .iter()
        .position(|c| !(c[0].is_finite() && c[1].is_finite()))
    {
        return Err(MeshError::Inconsistent {
            what: format!("texture coordinate {k} is not finite"),
        });
    }
    Ok(())
}

/// The pieces of a mesh (flatten's pattern pieces, fl-mesh's independent parts): one per
/// connected component of each patch, in patch order, as its name (the patch
/// name, `#k` appended when a patch has several components) and its faces.
pub fn patch_components(mesh: &Mesh) -> Vec<(String, Vec<u32>)> {
    let nf = mesh.num_faces();
    let fp = mesh.face_patch();
    let mut sets = disjoint::DisjointSets::new(nf);
    for ef in mesh.conn().edge_faces() {
        if ef[1] != NONE && fp[ef[0] as usize] == fp[ef[1] as usize] {
            sets.union(ef[0], ef[1]);
        }
    }
    let mut comps: Vec<Vec<Vec<u32>>> = vec![Vec::new(); mesh.num_patches()];
    let mut comp_of_root: std::collections::HashMap<u32, (usize, usize)> =
        std::collections::HashMap::new();
    for f in 0..nf as u32 {
        let r = sets.find(f);
        let p = fp[f as usize] as usize;
        let (pp, k) = *comp_of_root.entry(r).or_insert_with(|| {
            comps[p].push(Vec::new());
            (p, comps[p].len() - 1)
        });
        comps[pp][k].push(f);
    }
    let mut out = Vec::new();
    for (p, cs) in comps.into_iter().enumerate() {
        let many = cs.len() > 1;
        for (k, faces) in cs.into_iter().enumerate() {
            let base = &mesh.patch_names()[p];
            let name = if many {
                format!("{base}#{}", k + 1)
            } else {
                base.clone()
            };
            out.push((name, faces));
        }
    }
    out
}

/// The boundary edges grouped by the positions of their two ends, bit for bit and in either
/// order, each group in ascending edge order (the groups in no set order). A group of two or
/// more is an edge left unwelded: a seam between panels exported apart, or a slit opened by
/// copies (fl-mesh moves such copies as one, flatten sews them).
pub fn boundary_edges_by_position(mesh: &Mesh) -> Vec<Vec<usize>> {
    let conn = mesh.conn();
    let key = |v: u32| mesh.position(v).map(f64::to_bits);
    let mut groups: std::collections::HashMap<[[u64; 3]; 2], Vec<usize>> =
        std::collections::HashMap::new();
    for (e, faces) in conn.edge_faces().iter().enumerate() {
        if faces[1] == NONE {
            let [a, b] = conn.edges()[e];
            let (ka, kb) = (key(a), key(b));
            groups.entry([ka.min(kb), ka.max(kb)]).or_default().push(e);
        }
    }
    groups.into_values().collect()
}

/// The bounding box of points.
pub fn bbox_of(points: impl Iterator<Item = [f64; 3]>) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Largest coordinate magnitude accepted: squared lengths stay far inside f64 and positions
/// inside f32 (glTF output).
pub const MAX_COORDINATE: f64 = 1e30;
/// Smallest bounding-box diagonal accepted: products of lengths (areas, squared lengths) stay
/// far above f64's underflow.
pub const MIN_EXTENT: f64 = 1e-30;

fn check_finite(positions: &[[f64; 3]]) -> Result<(), MeshError> {
    for (i, p) in positions.iter().enumerate() {
        for (k, &x) in p.iter().enumerate() {
            let axis = ['x', 'y', 'z'][k];
            if !x.is_finite() {
                return Err(MeshError::NonFinite {
                    vertex: i,
                    axis,
                    value: x,
                });
            }
            if x.abs() > MAX_COORDINATE {
                return Err(MeshError::OutOfRange {
                    vertex: i,
                    axis,
                    value: x,
                });
            }
        }
    }
    let (lo, hi) = bbox_of(positions.iter().copied());
    let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    if !positions.is_empty() && diagonal < MIN_EXTENT {
        return Err(MeshError::TooSmall { diagonal });
    }
    Ok(())
}

fn check_faces(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Result<(), MeshError> {
    for (f, t) in triangles.iter().enumerate() {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return Err(MeshError::DegenerateFace {
                face: f,
                vertices: *t,
                reason: "repeated vertex",
            });
        }
        let [a, b, c] = [
            positions[t[0] as usize],
            positions[t[1] as usize],
            positions[t[2] as usize],
        ];
        if is_degenerate_triangle(a, b, c) {
            return Err(MeshError::DegenerateFace {
                face: f,
                vertices: *t,
                reason: "zero area",
            });
        }
    }
    Ok(())
}

/// Whether a triangle counts as zero-area: twice its area at most [`DEGENERATE_REL_AREA`]
/// times its longest edge squared (a sliver, whatever its size), or not finite. The one test
/// shared by validation and by the optimisers, so an iterate they accept always validates.
pub fn is_degenerate_triangle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    let e0 = sub(b, a);
    let e1 = sub(c, b);
    let e2 = sub(a, c);
    let cr = cross(e0, sub(c, a));
    let area2 = dot(cr, cr).sqrt();
    let lmax2 = dot(e0, e0).max(dot(e1, e1)).max(dot(e2, e2));
    area2 <= DEGENERATE_REL_AREA * lmax2 || !area2.is_finite()
}

#[inline]
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
