//! Wavefront OBJ reader and writer.
//!
//! Hand-written rather than tobj because we need what tobj does not give (../shared/CRATES.md):
//! vertex i of the mesh is the file's i-th `v` line, `o` and `g` are told apart, and faces with
//! fewer than three vertices or out-of-range `vt`/`vn` indices are refused with their line
//! number instead of being accepted silently.
//!
//! Patches: each distinct (`o`, `g`) pair that has faces is one patch, named `g`, `o`, or
//! `o/g` when both are given; faces before any `o`/`g` go to patch `default`. Polygons are
//! triangulated by ear clipping in their best-fit plane, so non-convex polygons come out right;
//! a quad is split along a diagonal whose two triangles face the same way, the shorter when
//! both (or neither, a twisted quad) do.

use super::ReadError;
use crate::mesh::{RawMesh, UvLayer, Warning};
use std::collections::HashMap;
use std::fmt::Write;

/// Ear clipping is quadratic to cubic in a polygon's size; faces this large are not surface
/// meshes but outlines, and would let one line of input stall the reader.
pub const MAX_POLYGON: usize = 1024;

/// Distinct unknown keywords counted one by one; statements of any further ones are counted
/// together.
const MAX_IGNORED_KINDS: usize = 64;

fn syntax(line: usize, message: impl Into<String>) -> ReadError {
    ReadError::Syntax {
        format: "OBJ",
        line,
        message: message.into(),
    }
}

fn parse_f64(tok: Option<&str>, line: usize, what: &str) -> Result<f64, ReadError> {
    let tok = tok.ok_or_else(|| syntax(line, format!("missing {what}")))?;
    tok.parse::<f64>()
        .map_err(|_| syntax(line, format!("{what} {tok:?} is not a number")))
}

/// Resolve an OBJ index (1-based, or negative relative to the `count` elements read so far).
fn resolve(tok: &str, count: usize, line: usize, what: &str) -> Result<u32, ReadError> {
    let i: i64 = tok
        .parse()
        .map_err(|_| syntax(line, format!("{what} index {tok:?} is not an integer")))?;
    let idx = if i > 0 {
        i - 1
    } else if i < 0 {
        count as i64 + i
    } else {
        return Err(syntax(
            line,
            format!("{what} index 0 is invalid (OBJ counts from 1)"),
        ));
    };
    if idx < 0 || idx >= count as i64 {
        return Err(syntax(
            line,
            format!("{what} index {i} is out of range ({count} defined so far)"),
        ));
    }
    Ok(idx as u32)
}

/// Parse OBJ bytes.
pub fn read(bytes: &[u8]) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    read_limited(bytes, &super::Limits::default())
}

/// [`read`] within `limits`: triangles are counted as polygons are triangulated, names cut
/// to [`super::MAX_NAME_BYTES`], ignored statements counted in a hash map (a file of many
/// distinct unknown keywords stays linear) and listed in the warning only up to ten.
pub fn read_limited(
    bytes: &[u8],
    limits: &super::Limits,
) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    let mut raw = RawMesh::default();
    let mut uvs: Vec<[f64; 2]> = Vec::new();
    let mut uv_tris: Vec<[u32; 3]> = Vec::new();
    let mut faces_with_uv = 0usize;
    let mut n_normals = 0usize;
    let mut object = String::new();
    let mut group = String::new();
    let mut patch_ids: HashMap<(String, String), u32> = HashMap::new();
    let mut current: Option<u32> = None;
    // Statements skipped, by keyword (the first MAX_IGNORED_KINDS keywords, in file order).
    let mut ignored: HashMap<String, usize> = HashMap::new();
    let mut ignored_order: Vec<String> = Vec::new();
    let mut ignored_other = 0usize;
    let mut names_cut = 0usize;
    let mut poly: Vec<(u32, Option<u32>)> = Vec::new();
    let mut tri_buf: Vec<[usize; 3]> = Vec::new();
    let mut scratch = EarScratch::default();

    let mut line_no = 0usize;
    let mut pending = String::new();
    // One empty line after the last, so that a file ending in a continuation (`\\` and no
    // newline) still ends its statement.
    for raw_line in bytes.split(|&b| b == b'\n').chain(std::iter::once(&[][..])) {
        line_no += 1;
        let text = String::from_utf8_lossy(raw_line);
        let mut text: &str = text.trim_end_matches('\r');
        if line_no == 1 {
            text = text.trim_start_matches('\u{feff}');
        }
        // Line continuation with a trailing backslash.
        if let Some(stripped) = text.strip_suffix('\\') {
            pending.push_str(stripped);
            pending.push(' ');
            continue;
        }
        let joined;
        if !pending.is_empty() {
            pending.push_str(text);
            joined = std::mem::take(&mut pending);
            text = &joined;
        }
        let text = match text.find('#') {
            Some(i) => &text[..i],
            None => text,
        };
        let mut toks = text.split_ascii_whitespace();
        let Some(key) = toks.next() else { continue };
        match key {
            "v" => {
                let x = parse_f64(toks.next(), line_no, "x coordinate")?;
                let y = parse_f64(toks.next(), line_no, "y coordinate")?;
                let z = parse_f64(toks.next(), line_no, "z coordinate")?;
                if raw.positions.len() >= limits.max_triangles {
                    return Err(ReadError::TooLarge {
                        what: format!("vertices up to line {line_no}"),
                        limit: limits.max_triangles,
                    });
                }
                raw.positions.push([x, y, z]);
            }
            "vt" => {
                let u = parse_f64(toks.next(), line_no, "u coordinate")?;
                let v = match toks.next() {
                    Some(t) => parse_f64(Some(t), line_no, "v coordinate")?,
                    None => 0.0,
                };
                if uvs.len() >= limits.max_triangles {
                    return Err(ReadError::TooLarge {
                        what: format!("texture coordinates up to line {line_no}"),
                        limit: limits.max_triangles,
                    });
                }
                uvs.push([u, v]);
            }
            "vn" => {
                for what in ["normal x", "normal y", "normal z"] {
                    parse_f64(toks.next(), line_no, what)?;
                }
                n_normals += 1;
            }
            "f" | "fo" => {
                poly.clear();
                for tok in toks {
                    let mut parts = tok.split('/');
                    let v = resolve(
                        parts.next().unwrap_or(""),
                        raw.positions.len(),
                        line_no,
                        "vertex",
                    )?;
                    let vt = match parts.next() {
                        Some("") | None => None,
                        Some(t) => Some(resolve(t, uvs.len(), line_no, "texture")?),
                    };
                    if let Some(t) = parts.next() {
                        if !t.is_empty() {
                            resolve(t, n_normals, line_no, "normal")?;
                        }
                    }
                    if parts.next().is_some() {
                        return Err(syntax(line_no, format!("malformed face vertex {tok:?}")));
                    }
                    // Checked as it grows: a face line can be as long as the file.
                    if poly.len() == MAX_POLYGON {
                        return Err(syntax(
                            line_no,
                            format!("face with more than {MAX_POLYGON} vertices (not supported)"),
                        ));
                    }
                    poly.push((v, vt));
                }
                if poly.len() > MAX_POLYGON {
                    return Err(syntax(
                        line_no,
                        format!(
                            "face with {} vertices (at most {MAX_POLYGON} supported)",
                            poly.len()
                        ),
                    ));
                }
                if poly.len() < 3 {
                    return Err(syntax(
                        line_no,
                        format!("face with {} vertices (at least 3 needed)", poly.len()),
                    ));
                }
                let has_uv = poly.iter().all(|p| p.1.is_some());
                let patch = match current {
                    Some(p) => p,
                    None => {
                        let key = (object.clone(), group.clone());
                        let next = patch_ids.len() as u32;
                        let p = *patch_ids.entry(key).or_insert_with(|| {
                            raw.patch_names.push(patch_name(&object, &group));
                            next
                        });
                        current = Some(p);
                        p
                    }
                };
                tri_buf.clear();
                if poly.len() == 3 {
                    tri_buf.push([0, 1, 2]);
                } else {
                    let pts: Vec<[f64; 3]> =
                        poly.iter().map(|p| raw.positions[p.0 as usize]).collect();
                    triangulate_polygon(&pts, &mut tri_buf, &mut scratch);
                }
                if raw.triangles.len() + tri_buf.len() > limits.max_triangles {
                    return Err(ReadError::TooLarge {
                        what: format!("triangles of the faces up to line {line_no}"),
                        limit: limits.max_triangles,
                    });
                }
                for t in &tri_buf {
                    raw.triangles
                        .push([poly[t[0]].0, poly[t[1]].0, poly[t[2]].0]);
                    raw.face_patch.push(patch);
                    if has_uv {
                        uv_tris.push([
                            poly[t[0]].1.unwrap_or(0),
                            poly[t[1]].1.unwrap_or(0),
                            poly[t[2]].1.unwrap_or(0),
                        ]);
                        faces_with_uv += 1;
                    } else {
                        uv_tris.push([0; 3]);
                    }
                }
            }
            "o" | "g" => {
                let name = toks.collect::<Vec<_>>().join(" ");
                let (kept, cut) = super::cap_name(&name);
                if cut {
                    names_cut += 1;
                }
                if key == "o" {
                    object = kept.to_string();
                } else {
                    group = kept.to_string();
                }
                current = None;
            }
            other => {
                if let Some(n) = ignored.get_mut(other) {
                    *n += 1;
                } else if ignored.len() < MAX_IGNORED_KINDS {
                    ignored.insert(other.to_string(), 1);
                    ignored_order.push(other.to_string());
                } else {
                    ignored_other += 1;
                }
            }
        }
    }
    let mut warnings = Vec::new();
    // Statements that carry no geometry we use are skipped; say so only for the unusual ones.
    let unusual: Vec<&String> = ignored_order
        .iter()
        .filter(|k| !matches!(k.as_str(), "s" | "usemtl" | "mtllib" | "vp"))
        .collect();
    if !unusual.is_empty() || ignored_other > 0 {
        let mut shown: Vec<String> = unusual
            .iter()
            .take(10)
            .map(|k| {
                let (short, cut) = super::cap_name(k);
                let short: String = short.chars().take(32).collect();
                let ell = if cut || short.len() < k.len() {
                    "…"
                } else {
                    ""
                };
                format!("{short}{ell} ({})", ignored[*k])
            })
            .collect();
        let rest: usize =
            unusual.iter().skip(10).map(|k| ignored[*k]).sum::<usize>() + ignored_other;
        if rest > 0 {
            shown.push(format!("{rest} more of other keywords"));
        }
        warnings.push(Warning::new(
            "obj_statements_ignored",
            format!("OBJ statements ignored: {}", shown.join(", ")),
        ));
    }
    if names_cut > 0 {
        warnings.push(Warning::new(
            "names_shortened",
            format!(
                "{names_cut} object or group names were longer than {} bytes and were cut",
                super::MAX_NAME_BYTES
            ),
        ));
    }
    if faces_with_uv == raw.triangles.len() && !raw.triangles.is_empty() {
        raw.uv = Some(UvLayer {
            coords: uvs,
            triangles: uv_tris,
        });
    } else if faces_with_uv > 0 {
        warnings.push(Warning::new(
            "partial_texture_coordinates",
            format!(
                "only {faces_with_uv} of {} triangles have texture coordinates; they were ignored",
                raw.triangles.len()
            ),
        ));
    }
    Ok((raw, warnings))
}

fn patch_name(object: &str, group: &str) -> String {
    match (object.is_empty(), group.is_empty()) {
        (true, true) => "default".to_string(),
        (true, false) => group.to_string(),
        (false, true) => object.to_string(),
        (false, false) => format!("{object}/{group}"),
    }
}

/// Reusable buffers for [`triangulate_polygon`].
#[derive(Default)]
pub struct EarScratch {
    p2: Vec<[f64; 2]>,
    idx: Vec<usize>,
}

/// Triangulate a simple polygon (3D points, in order) by ear clipping in the plane of its
/// Newell normal. Output triangles index `pts` and keep the polygon's orientation. A polygon
/// with no usable plane (all points collinear) is fanned; validation then names the
/// degenerate face.
pub fn triangulate_polygon(pts: &[[f64; 3]], out: &mut Vec<[usize; 3]>, s: &mut EarScratch) {
    let n = pts.len();
    let mut nrm = [0.0f64; 3];
    for i in 0..n {
        let a = pts[i];
        let b = pts[(i + 1) % n];
        nrm[0] += (a[1] - b[1]) * (a[2] + b[2]);
        nrm[1] += (a[2] - b[2]) * (a[0] + b[0]);
        nrm[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    let len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
    if len.is_nan() || len == 0.0 || !len.is_finite() {
        for i in 1..n - 1 {
            out.push([0, i, i + 1]);
        }
        return;
    }
    let nz = [nrm[0] / len, nrm[1] / len, nrm[2] / len];
    // Orthonormal basis (u, w) with u × w = n, so the polygon is counter-clockwise in 2D.
    let helper = if nz[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = crate::geometry::normalize(crate::mesh::cross(helper, nz));
    let w = crate::mesh::cross(nz, u);
    s.p2.clear();
    s.p2.extend(pts.iter().map(|p| {
        [
            p[0] * u[0] + p[1] * u[1] + p[2] * u[2],
            p[0] * w[0] + p[1] * w[1] + p[2] * w[2],
        ]
    }));
    s.idx.clear();
    s.idx.extend(0..n);
    let p = &s.p2;
    let cross2 = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    // A quad is split along a diagonal whose two triangles face the same way (a planar
    // non-convex quad has one); when both do, or neither (a twisted quad, folded in any
    // split), along the shorter, measured in 3D. The rule does not depend on where the face
    // starts, and for a non-planar convex quad the shorter diagonal is the flatter split.
    if n == 4 {
        let d = |a: usize, b: usize| {
            let v = crate::mesh::sub(pts[a], pts[b]);
            crate::mesh::dot(v, v)
        };
        let normal = |a: usize, b: usize, c: usize| {
            crate::mesh::cross(
                crate::mesh::sub(pts[b], pts[a]),
                crate::mesh::sub(pts[c], pts[a]),
            )
        };
        let ok13 = crate::mesh::dot(normal(0, 1, 3), normal(1, 2, 3)) > 0.0;
        let ok02 = crate::mesh::dot(normal(0, 1, 2), normal(0, 2, 3)) > 0.0;
        let use13 = if ok13 == ok02 {
            d(1, 3) < d(0, 2)
        } else {
            ok13
        };
        if use13 {
            out.push([0, 1, 3]);
            out.push([1, 2, 3]);
        } else {
            out.push([0, 1, 2]);
            out.push([0, 2, 3]);
        }
        return;
    }
    while s.idx.len() > 3 {
        let m = s.idx.len();
        let mut best: Option<(usize, f64)> = None;
        let mut ear = None;
        for k in 0..m {
            let (ia, ib, ic) = (s.idx[(k + m - 1) % m], s.idx[k], s.idx[(k + 1) % m]);
            let area = cross2(p[ia], p[ib], p[ic]);
            if best.is_none_or(|(_, a)| area > a) {
                best = Some((k, area));
            }
            if area <= 0.0 {
                continue;
            }
            let inside = s.idx.iter().any(|&j| {
                j != ia
                    && j != ib
                    && j != ic
                    && cross2(p[ia], p[ib], p[j]) >= 0.0
                    && cross2(p[ib], p[ic], p[j]) >= 0.0
                    && cross2(p[ic], p[ia], p[j]) >= 0.0
            });
            if !inside {
                ear = Some(k);
                break;
            }
        }
        // No clean ear only happens on self-intersecting input: clip the fattest corner.
        let k = ear.unwrap_or(best.map_or(0, |b| b.0));
        let m = s.idx.len();
        out.push([s.idx[(k + m - 1) % m], s.idx[k], s.idx[(k + 1) % m]]);
        s.idx.remove(k);
    }
    out.push([s.idx[0], s.idx[1], s.idx[2]]);
}

/// Write `raw` as OBJ: every vertex in order (so indices are kept), then each patch's faces
/// under `g <name>`, with `vt` when the mesh has texture coordinates. Coordinates are written
/// with Rust's shortest round-trip formatting, so reading back gives the same f64 values.
pub fn write(raw: &RawMesh) -> String {
    let mut s = String::with_capacity(raw.positions.len() * 40 + raw.triangles.len() * 24);
    s.push_str("# written by flatmesh\n");
    for p in &raw.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if let Some(uv) = &raw.uv {
        for t in &uv.coords {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
    }
    let np = raw.patch_names.len().max(1);
    let mut by_patch: Vec<Vec<usize>> = vec![Vec::new(); np];
    for (f, &p) in raw.face_patch.iter().enumerate() {
        by_patch[(p as usize).min(np - 1)].push(f);
    }
    if raw.face_patch.is_empty() {
        by_patch[0] = (0..raw.triangles.len()).collect();
    }
    for (p, faces) in by_patch.iter().enumerate() {
        if faces.is_empty() {
            continue;
        }
        let name = raw
            .patch_names
            .get(p)
            .map(|n| sanitize(n))
            .unwrap_or_else(|| "default".to_string());
        let _ = writeln!(s, "g {name}");
        for &f in faces {
            let t = raw.triangles[f];
            match &raw.uv {
                Some(uv) => {
                    let u = uv.triangles[f];
                    let _ = writeln!(
                        s,
                        "f {}/{} {}/{} {}/{}",
                        t[0] + 1,
                        u[0] + 1,
                        t[1] + 1,
                        u[1] + 1,
                        t[2] + 1,
                        u[2] + 1
                    );
                }
                None => {
                    let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
                }
            }
        }
    }
    s
}

/// Patch names go on one `g` line: no line breaks, no comment marker, not empty.
fn sanitize(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| if c == '#' || c.is_control() { '_' } else { c })
        .collect();
    let s = s.trim().to_string();
    if s.is_empty() {
        "default".to_string()
    } else {
        s
    }
}
