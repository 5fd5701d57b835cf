//! OFF (Object File Format) reader, for research meshes: `OFF` (or `COFF`/`NOFF`/`CNOFF`)
//! header, counts, vertices, then faces as `n i0 … i(n−1) [colour]`; polygons are
//! triangulated like OBJ's. One patch, `default`.

use super::obj::{triangulate_polygon, EarScratch};
use super::ReadError;
use crate::mesh::{RawMesh, Warning};

fn syntax(line: usize, message: impl Into<String>) -> ReadError {
    ReadError::Syntax {
        format: "OFF",
        line,
        message: message.into(),
    }
}

/// Parse OFF bytes.
pub fn read(bytes: &[u8]) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    read_limited(bytes, &super::Limits::default())
}

/// [`read`] within `limits` (the header's counts are checked before anything is read).
pub fn read_limited(
    bytes: &[u8],
    limits: &super::Limits,
) -> Result<(RawMesh, Vec<Warning>), ReadError> {
    let text = String::from_utf8_lossy(bytes);
    // Tokens with their line numbers, comments removed.
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty());
    let (hline, header) = lines.next().ok_or_else(|| syntax(1, "empty file"))?;
    let mut head_toks = header.split_ascii_whitespace();
    let magic = head_toks.next().unwrap_or("");
    let with_normals = magic.contains('N');
    if !magic.ends_with("OFF") || magic.contains("ST") || magic.contains('4') || magic.contains("n")
    {
        return Err(syntax(hline, format!("unsupported OFF header {magic:?}")));
    }
    // Counts may follow the header on the same line.
    let rest: Vec<&str> = head_toks.collect();
    let (cline, counts): (usize, Vec<&str>) = if rest.is_empty() {
        let (l, c) = lines
            .next()
            .ok_or_else(|| syntax(hline, "missing counts"))?;
        (l, c.split_ascii_whitespace().collect())
    } else {
        (hline, rest)
    };
    let count = |i: usize, what: &str| -> Result<usize, ReadError> {
        counts
            .get(i)
            .ok_or_else(|| syntax(cline, format!("missing {what} count")))?
            .parse::<usize>()
            .map_err(|_| syntax(cline, format!("{what} count is not a non-negative integer")))
    };
    let nv = count(0, "vertex")?;
    let nf = count(1, "face")?;
    for (n, what) in [(nv, "vertices"), (nf, "faces")] {
        if n > limits.max_triangles {
            return Err(ReadError::TooLarge {
                what: format!("the OFF header announces {n} {what}"),
                limit: limits.max_triangles,
            });
        }
    }
    let mut raw = RawMesh {
        // Capacity bounded by what the file can hold (a vertex line takes at least 6 bytes), so
        // a forged count cannot make us allocate; a short file then ends early with an error.
        positions: Vec::with_capacity(nv.min(bytes.len() / 6)),
        patch_names: vec!["default".to_string()],
        ..RawMesh::default()
    };
    for _ in 0..nv {
        let (l, t) = lines
            .next()
            .ok_or_else(|| syntax(cline, format!("expected {nv} vertices, file ended early")))?;
        let mut it = t.split_ascii_whitespace();
        let mut p = [0.0; 3];
        for (k, c) in p.iter_mut().enumerate() {
            let tok = it.next().ok_or_else(|| {
                syntax(
                    l,
                    format!("vertex has no {} coordinate", ["x", "y", "z"][k]),
                )
            })?;
            *c = tok
                .parse()
                .map_err(|_| syntax(l, format!("coordinate {tok:?} is not a number")))?;
        }
        let _ = with_normals;
        raw.positions.push(p);
    }
    let mut poly = Vec::new();
    let mut pts = Vec::new();
    let mut tris = Vec::new();
    let mut scratch = EarScratch::default();
    for _ in 0..nf {
        let (l, t) = lines
            .next()
            .ok_or_else(|| syntax(cline, format!("expected {nf} faces, file ended early")))?;
        let mut it = t.split_ascii_whitespace();
        let n: usize = it
            .next()
            .unwrap_or("")
            .parse()
            .map_err(|_| syntax(l, "face does not start with its vertex count"))?;
        if n > super::obj::MAX_POLYGON {
            return Err(syntax(
                l,
                format!(
                    "face with {n} vertices (at most {} supported)",
                    super::obj::MAX_POLYGON
                ),
            ));
        }
        if n < 3 {
            return Err(syntax(
                l,
                format!("face with {n} vertices (at least 3 needed)"),
            ));
        }
        poly.clear();
        for _ in 0..n {
            let tok = it
                .next()
                .ok_or_else(|| syntax(l, format!("face announces {n} vertices but has fewer")))?;
            let i: usize = tok
                .parse()
                .map_err(|_| syntax(l, format!("vertex index {tok:?} is not an integer")))?;
            if i >= nv {
                return Err(syntax(
                    l,
                    format!("vertex index {i} out of range ({nv} vertices)"),
                ));
            }
            poly.push(i as u32);
        }
        tris.clear();
        if n == 3 {
            tris.push([0, 1, 2]);
        } else {
            pts.clear();
            pts.extend(poly.iter().map(|&i| raw.positions[i as usize]));
            triangulate_polygon(&pts, &mut tris, &mut scratch);
        }
        if raw.triangles.len() + tris.len() > limits.max_triangles {
            return Err(ReadError::TooLarge {
                what: format!("triangles of the polygons up to line {l}"),
                limit: limits.max_triangles,
            });
        }
        for t in &tris {
            raw.triangles.push([poly[t[0]], poly[t[1]], poly[t[2]]]);
            raw.face_patch.push(0);
        }
    }
    Ok((raw, Vec::new()))
}
