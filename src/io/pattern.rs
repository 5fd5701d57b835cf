//! Pattern export: JSON (mesh units), SVG and DXF (drawing units), and a minimal DXF reader
//! used by the tests to read outlines back.
//!
//! Drawings place the pieces side by side without overlap (shelf packing of their bounding
//! boxes, tallest first) and scale mesh units to the drawing unit (`Patterns::input_unit` →
//! `Patterns::unit`). The SVG flips y (SVG's y points down) so pieces are not mirrored; the
//! DXF keeps y up. Both use the same placement, [`layout`].

use crate::pattern::Patterns;
use std::fmt::Write;

pub use crate::pattern::mm_per;

/// Drawing units per mesh unit (1 when a unit is missing or unknown).
pub fn scale(p: &Patterns) -> f64 {
    p.scale()
}

/// Placement of each piece in the drawing ([`Patterns::layout`]).
pub fn layout(p: &Patterns) -> (Vec<[f64; 2]>, f64, f64) {
    p.layout()
}

/// `patterns.json`.
pub fn to_json(p: &Patterns) -> String {
    serde_json::to_string_pretty(p).unwrap_or_else(|_| "{}".into())
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `patterns.svg`: one `<g>` per piece (outlines, optionally triangles, name), seam labels
/// `S<k>` at the middle edge of each seam on both pieces; width and height in real units.
pub fn to_svg(p: &Patterns) -> String {
    let s = scale(p);
    let (off, w, h) = layout(p);
    let unit = if mm_per(&p.unit).is_some() {
        p.unit.as_str()
    } else {
        ""
    };
    // SVG lengths know mm, cm, in but not m or dm: write those as centimetres.
    let (wu, hu, uname) = match unit {
        "m" => (w * 100.0, h * 100.0, "cm"),
        "dm" => (w * 10.0, h * 10.0, "cm"),
        _ => (w, h, unit),
    };
    let stroke = (w.max(h) / 1500.0).max(f64::MIN_POSITIVE);
    let font = (w.max(h) / 80.0).max(f64::MIN_POSITIVE);
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{wu}{uname}" height="{hu}{uname}" viewBox="0 0 {w} {h}" font-family="DejaVu Sans, Arial, Helvetica, sans-serif">
<!-- flatmesh patterns: 1 user unit = 1 {u}; mesh unit {iu} -->"#,
        u = esc(&p.unit),
        iu = esc(&p.input_unit)
    );
    let pt = |i: usize, q: [f64; 2]| -> (f64, f64) {
        let x = q[0] * s + off[i][0];
        let y = q[1] * s + off[i][1];
        (x, h - y)
    };
    for (i, pc) in p.pieces.iter().enumerate() {
        let _ = writeln!(out, r#"<g id="piece-{i}" data-patch="{}">"#, esc(&pc.patch));
        if p.svg_triangles {
            let mut d = String::new();
            for t in &pc.triangles {
                let (a, b, c) = (
                    pt(i, pc.uv[t[0] as usize]),
                    pt(i, pc.uv[t[1] as usize]),
                    pt(i, pc.uv[t[2] as usize]),
                );
                let _ = write!(d, "M{} {}L{} {}L{} {}Z", a.0, a.1, b.0, b.1, c.0, c.1);
            }
            let _ = writeln!(
                out,
                r##"<path d="{d}" fill="none" stroke="#9ab" stroke-width="{}"/>"##,
                stroke * 0.4
            );
        }
        // Cut line solid; the sew line dashed inside it (solid when there is no cut line).
        for lp in &pc.cut_lines {
            let d = path_of(lp.iter().map(|&q| pt(i, q)));
            let _ = writeln!(
                out,
                r##"<path class="cut" d="{d}Z" fill="none" stroke="#000" stroke-width="{stroke}"/>"##
            );
        }
        let dash = if pc.cut_lines.is_empty() {
            String::new()
        } else {
            format!(r#" stroke-dasharray="{} {}""#, stroke * 8.0, stroke * 4.0)
        };
        for lp in &pc.boundary_loops {
            let d = path_of(lp.iter().map(|&v| pt(i, pc.uv[v as usize])));
            let _ = writeln!(
                out,
                r##"<path class="sew" d="{d}Z" fill="none" stroke="#000" stroke-width="{}"{dash}/>"##,
                stroke * 0.7
            );
        }
        // Notches: across the allowance, from the cut line to the sew line (a short tick into
        // the piece when there is no allowance).
        let mut d = String::new();
        for n in &pc.notches {
            let a = pt(i, n.cut_at);
            let b = if n.cut_at == n.at {
                let q = [
                    n.at[0] + n.inward[0] * font / s,
                    n.at[1] + n.inward[1] * font / s,
                ];
                pt(i, q)
            } else {
                pt(i, n.at)
            };
            let _ = write!(d, "M{} {}L{} {}", a.0, a.1, b.0, b.1);
        }
        if !d.is_empty() {
            let _ = writeln!(
                out,
                r##"<path class="notches" d="{d}" fill="none" stroke="#c00" stroke-width="{}"/>"##,
                stroke * 1.5
            );
        }
        if let Some([a, b]) = pc.grain {
            let (a, b) = (pt(i, a), pt(i, b));
            let h = font * 0.6;
            let _ = writeln!(
                out,
                r##"<path class="grain" d="M{} {}L{} {}M{} {}L{} {}L{} {}M{} {}L{} {}L{} {}" fill="none" stroke="#06c" stroke-width="{stroke}"/>"##,
                a.0,
                a.1,
                b.0,
                b.1,
                b.0 - h * 0.5,
                b.1 + h,
                b.0,
                b.1,
                b.0 + h * 0.5,
                b.1 + h,
                a.0 - h * 0.5,
                a.1 - h,
                a.0,
                a.1,
                a.0 + h * 0.5,
                a.1 - h
            );
        }
        // The name beside the grain line (or at the centroid), no taller than a tenth of the
        // piece, so that small pieces' names do not run into each other.
        let (lo, hi) = pc
            .uv
            .iter()
            .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), q| {
                (
                    [lo[0].min(q[0]), lo[1].min(q[1])],
                    [hi[0].max(q[0]), hi[1].max(q[1])],
                )
            });
        let size = font
            .min(0.1 * (hi[0] - lo[0]).max(hi[1] - lo[1]) * s)
            .max(f64::MIN_POSITIVE);
        let anchor = pc
            .grain
            .map(|[a, b]| ([(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0], "start"))
            .or_else(|| centroid(&pc.uv).map(|c| (c, "middle")));
        if let Some((c, how)) = anchor {
            let (x, y) = pt(i, c);
            let dx = if how == "start" { size * 0.4 } else { 0.0 };
            let _ = writeln!(
                out,
                r#"<text x="{}" y="{y}" font-size="{size}" text-anchor="{how}">{}</text>"#,
                x + dx,
                esc(&pc.patch)
            );
        }
        let _ = writeln!(out, "</g>");
    }
    let _ = writeln!(out, r##"<g id="seams" fill="#c00">"##);
    for (k, sm) in p.seams.iter().enumerate() {
        for side in 0..2 {
            let pi = sm.pieces[side];
            let Some(pc) = p.pieces.get(pi) else { continue };
            let edges = &sm.edges[side];
            if edges.is_empty() {
                continue;
            }
            let e = edges[edges.len() / 2];
            let (a, b) = (pc.uv[e[0] as usize], pc.uv[e[1] as usize]);
            let (x, y) = pt(pi, [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]);
            // No larger than half the seam, so that short seams' labels stay apart.
            let size = (font * 0.7)
                .min(0.5 * sm.lengths[side] * s)
                .max(f64::MIN_POSITIVE);
            let _ = writeln!(
                out,
                r#"<text x="{x}" y="{y}" font-size="{size}" text-anchor="middle">S{k}</text>"#
            );
        }
    }
    let _ = writeln!(out, "</g>\n</svg>");
    out
}

/// An SVG path's `M x y L x y …` through the points.
fn path_of(points: impl Iterator<Item = (f64, f64)>) -> String {
    let mut d = String::new();
    for (k, (x, y)) in points.enumerate() {
        let _ = write!(d, "{}{} {}", if k == 0 { "M" } else { "L" }, x, y);
    }
    d
}

fn centroid(uv: &[[f64; 2]]) -> Option<[f64; 2]> {
    if uv.is_empty() {
        return None;
    }
    let n = uv.len() as f64;
    Some(
        uv.iter()
            .fold([0.0, 0.0], |s, q| [s[0] + q[0] / n, s[1] + q[1] / n]),
    )
}

/// A DXF layer name for a piece: `P<i>_` and the patch name with characters outside
/// `[A-Za-z0-9_-]` replaced by `_`, 31 characters at most (R12's limit; unique through i).
pub fn layer_name(i: usize, patch: &str) -> String {
    let head = format!("P{i}_");
    let clean: String = patch
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(31usize.saturating_sub(head.len()))
        .collect();
    format!("{head}{clean}")
}

/// Text for a DXF TEXT entity: one line, ASCII (others as `\U+XXXX`, as AutoCAD writes
/// them), `%` doubled into `%%%` so that it is not read as a control code.
fn dxf_text(t: &str) -> String {
    let mut out = String::new();
    for c in t.chars().take(250) {
        match c {
            '%' => out.push_str("%%%"),
            c if c.is_control() || c == '\u{2028}' || c == '\u{2029}' => out.push(' '),
            c if c.is_ascii() => out.push(c),
            c => {
                let _ = write!(out, "\\U+{:04X}", c as u32);
            }
        }
    }
    out
}

/// `patterns-plain.dxf` (`format=dxf-plain`): ASCII DXF R12; each boundary loop (sew line) of
/// each piece is a closed POLYLINE on the piece's own layer, in drawing units, placed by
/// [`layout`]. Coordinates are written with Rust's shortest round-trip formatting, so reading
/// them back gives the same doubles.
pub fn to_dxf_plain(p: &Patterns) -> String {
    let s = scale(p);
    let (off, w, h) = layout(p);
    let mut o = String::new();
    let mut pair = |code: i32, value: &str| {
        let _ = write!(o, "{code}\n{value}\n");
    };
    pair(0, "SECTION");
    pair(2, "HEADER");
    pair(9, "$ACADVER");
    pair(1, "AC1009");
    pair(9, "$EXTMIN");
    pair(10, "0");
    pair(20, "0");
    pair(9, "$EXTMAX");
    pair(10, &w.to_string());
    pair(20, &h.to_string());
    pair(0, "ENDSEC");
    pair(0, "SECTION");
    pair(2, "TABLES");
    pair(0, "TABLE");
    pair(2, "LAYER");
    pair(70, &p.pieces.len().to_string());
    for (i, pc) in p.pieces.iter().enumerate() {
        pair(0, "LAYER");
        pair(2, &layer_name(i, &pc.patch));
        pair(70, "0");
        pair(62, &((i % 254) + 1).to_string());
        pair(6, "CONTINUOUS");
    }
    pair(0, "ENDTAB");
    pair(0, "ENDSEC");
    pair(0, "SECTION");
    pair(2, "ENTITIES");
    for (i, pc) in p.pieces.iter().enumerate() {
        let layer = layer_name(i, &pc.patch);
        for lp in &pc.boundary_loops {
            pair(0, "POLYLINE");
            pair(8, &layer);
            pair(66, "1");
            pair(10, "0");
            pair(20, "0");
            pair(30, "0");
            pair(70, "1");
            for &v in lp {
                let q = pc.uv[v as usize];
                pair(0, "VERTEX");
                pair(8, &layer);
                pair(10, &(q[0] * s + off[i][0]).to_string());
                pair(20, &(q[1] * s + off[i][1]).to_string());
                pair(30, "0");
            }
            pair(0, "SEQEND");
            pair(8, &layer);
        }
    }
    pair(0, "ENDSEC");
    pair(0, "EOF");
    o
}

/// AAMA / ASTM D6673 layers used by [`to_dxf`].
pub mod aama {
    /// Piece boundary: the cut line, and the piece and style system text.
    pub const BOUNDARY: &str = "1";
    /// Notches (slit notches: a LINE from the boundary into the piece).
    pub const NOTCHES: &str = "4";
    /// Grain line.
    pub const GRAIN: &str = "7";
    /// Internal cut-outs: holes of the cut line.
    pub const INTERNAL_CUTOUTS: &str = "11";
    /// Sew lines.
    pub const SEW: &str = "14";
    /// Annotation text.
    pub const ANNOTATION: &str = "15";
}

/// A DXF block name for a piece: [`layer_name`]'s form, unique per piece.
pub fn block_name(i: usize, patch: &str) -> String {
    layer_name(i, patch)
}

/// Depth of a notch's slit in millimetres (a quarter inch), at most the allowance.
pub const NOTCH_DEPTH_MM: f64 = 6.35;

/// `patterns.dxf`: the AAMA / ASTM D6673 layout in ASCII DXF R12. One BLOCK per piece (in
/// drawing units, the piece's own coordinates) holding its cut line (layer 1; the sew line
/// when there is no allowance), holes of the cut line (11), sew lines (14), slit notches from
/// the cut line inwards (4), the grain line (7), and the piece system text `Piece Name:` and
/// `Quantity:` (1) with its seams as annotation (15); ENTITIES holds the style system text and
/// one INSERT per piece at its place in [`layout`].
pub fn to_dxf(p: &Patterns) -> String {
    let s = scale(p);
    let (off, w, h) = layout(p);
    let mm = mm_per(&p.unit).unwrap_or(1.0);
    let text_h = 5.0 / mm;
    let mut o = String::new();
    let pair = |o: &mut String, code: i32, value: &str| {
        let _ = write!(o, "{code}\n{value}\n");
    };
    let num = |x: f64| x.to_string();
    let polyline = |o: &mut String, layer: &str, pts: &mut dyn Iterator<Item = [f64; 2]>| {
        let mut w = |c: i32, v: &str| {
            let _ = write!(o, "{c}\n{v}\n");
        };
        w(0, "POLYLINE");
        w(8, layer);
        w(66, "1");
        w(10, "0");
        w(20, "0");
        w(30, "0");
        w(70, "1");
        for q in pts {
            w(0, "VERTEX");
            w(8, layer);
            w(10, &q[0].to_string());
            w(20, &q[1].to_string());
            w(30, "0");
        }
        w(0, "SEQEND");
        w(8, layer);
    };
    let line = |o: &mut String, layer: &str, a: [f64; 2], b: [f64; 2]| {
        let _ = write!(
            o,
            "0\nLINE\n8\n{layer}\n10\n{}\n20\n{}\n30\n0\n11\n{}\n21\n{}\n31\n0\n",
            a[0], a[1], b[0], b[1]
        );
    };
    let text = |o: &mut String, layer: &str, at: [f64; 2], height: f64, t: &str| {
        let clean = dxf_text(t);
        let _ = write!(
            o,
            "0\nTEXT\n8\n{layer}\n10\n{}\n20\n{}\n30\n0\n40\n{height}\n1\n{clean}\n",
            at[0], at[1]
        );
    };
    pair(&mut o, 0, "SECTION");
    pair(&mut o, 2, "HEADER");
    pair(&mut o, 9, "$ACADVER");
    pair(&mut o, 1, "AC1009");
    pair(&mut o, 9, "$EXTMIN");
    pair(&mut o, 10, "0");
    pair(&mut o, 20, "0");
    pair(&mut o, 9, "$EXTMAX");
    pair(&mut o, 10, &num(w));
    pair(&mut o, 20, &num(h));
    pair(&mut o, 0, "ENDSEC");
    pair(&mut o, 0, "SECTION");
    pair(&mut o, 2, "TABLES");
    pair(&mut o, 0, "TABLE");
    pair(&mut o, 2, "LAYER");
    let layers = [
        ("0", 7),
        (aama::BOUNDARY, 7),
        (aama::NOTCHES, 1),
        (aama::GRAIN, 5),
        (aama::INTERNAL_CUTOUTS, 7),
        (aama::SEW, 8),
        (aama::ANNOTATION, 3),
    ];
    pair(&mut o, 70, &layers.len().to_string());
    for (name, color) in layers {
        pair(&mut o, 0, "LAYER");
        pair(&mut o, 2, name);
        pair(&mut o, 70, "0");
        pair(&mut o, 62, &color.to_string());
        pair(&mut o, 6, "CONTINUOUS");
    }
    pair(&mut o, 0, "ENDTAB");
    pair(&mut o, 0, "ENDSEC");
    let mut seams_of: Vec<Vec<usize>> = vec![Vec::new(); p.pieces.len()];
    for (k, sm) in p.seams.iter().enumerate() {
        for side in 0..2 {
            if let Some(list) = seams_of.get_mut(sm.pieces[side]) {
                if list.last() != Some(&k) {
                    list.push(k);
                }
            }
        }
    }
    pair(&mut o, 0, "SECTION");
    pair(&mut o, 2, "BLOCKS");
    for (i, pc) in p.pieces.iter().enumerate() {
        let at = |q: [f64; 2]| [q[0] * s, q[1] * s];
        pair(&mut o, 0, "BLOCK");
        pair(&mut o, 8, "0");
        pair(&mut o, 2, &block_name(i, &pc.patch));
        pair(&mut o, 70, "0");
        pair(&mut o, 10, "0");
        pair(&mut o, 20, "0");
        pair(&mut o, 30, "0");
        if pc.cut_lines.is_empty() {
            for (k, lp) in pc.boundary_loops.iter().enumerate() {
                let layer = if k == 0 {
                    aama::BOUNDARY
                } else {
                    aama::INTERNAL_CUTOUTS
                };
                polyline(
                    &mut o,
                    layer,
                    &mut lp.iter().map(|&v| at(pc.uv[v as usize])),
                );
            }
        } else {
            for (k, lp) in pc.cut_lines.iter().enumerate() {
                let layer = if k == 0 {
                    aama::BOUNDARY
                } else {
                    aama::INTERNAL_CUTOUTS
                };
                polyline(&mut o, layer, &mut lp.iter().map(|&q| at(q)));
            }
            for lp in &pc.boundary_loops {
                polyline(
                    &mut o,
                    aama::SEW,
                    &mut lp.iter().map(|&v| at(pc.uv[v as usize])),
                );
            }
        }
        for n in &pc.notches {
            let reach =
                ((n.at[0] - n.cut_at[0]).powi(2) + (n.at[1] - n.cut_at[1]).powi(2)).sqrt() * s;
            let depth = if reach > 0.0 {
                reach.min(NOTCH_DEPTH_MM / mm)
            } else {
                NOTCH_DEPTH_MM / mm
            };
            let a = at(n.cut_at);
            line(
                &mut o,
                aama::NOTCHES,
                a,
                [a[0] + n.inward[0] * depth, a[1] + n.inward[1] * depth],
            );
        }
        if let Some([a, b]) = pc.grain {
            line(&mut o, aama::GRAIN, at(a), at(b));
        }
        let c = pc
            .grain
            .map(|[a, b]| [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0])
            .or_else(|| centroid(&pc.uv))
            .map(at)
            .unwrap_or([0.0, 0.0]);
        let x = c[0] + text_h;
        text(
            &mut o,
            aama::BOUNDARY,
            [x, c[1]],
            text_h,
            &format!("Piece Name: {}", pc.patch),
        );
        text(
            &mut o,
            aama::BOUNDARY,
            [x, c[1] - 1.5 * text_h],
            text_h,
            "Quantity: 1",
        );
        let seams: Vec<String> = seams_of[i]
            .iter()
            .map(|&k| (k, &p.seams[k]))
            .map(|(k, sm)| {
                let other = if sm.pieces[0] == i {
                    &sm.patches[1]
                } else {
                    &sm.patches[0]
                };
                format!("S{k} to {other}")
            })
            .collect();
        if !seams.is_empty() {
            text(
                &mut o,
                aama::ANNOTATION,
                [x, c[1] - 3.0 * text_h],
                text_h * 0.7,
                &format!("Seams: {}", seams.join(", ")),
            );
        }
        pair(&mut o, 0, "ENDBLK");
        pair(&mut o, 8, "0");
    }
    pair(&mut o, 0, "ENDSEC");
    pair(&mut o, 0, "SECTION");
    pair(&mut o, 2, "ENTITIES");
    let units = if p.unit == "in" { "ENGLISH" } else { "METRIC" };
    text(
        &mut o,
        aama::BOUNDARY,
        [0.0, -2.0 * text_h],
        text_h,
        "Style Name: flatmesh",
    );
    text(
        &mut o,
        aama::BOUNDARY,
        [0.0, -3.5 * text_h],
        text_h,
        &format!("Units: {units} ({})", p.unit),
    );
    for (i, pc) in p.pieces.iter().enumerate() {
        pair(&mut o, 0, "INSERT");
        pair(&mut o, 8, "0");
        pair(&mut o, 2, &block_name(i, &pc.patch));
        pair(&mut o, 10, &num(off[i][0]));
        pair(&mut o, 20, &num(off[i][1]));
        pair(&mut o, 30, "0");
    }
    pair(&mut o, 0, "ENDSEC");
    pair(&mut o, 0, "EOF");
    o
}

/// A polyline read back from a DXF.
#[derive(Debug, Clone, PartialEq)]
pub struct DxfPolyline {
    /// Layer name.
    pub layer: String,
    /// Whether flag 70 bit 1 (closed) is set.
    pub closed: bool,
    /// Vertices.
    pub points: Vec<[f64; 2]>,
}

/// Read the POLYLINE (R12) and LWPOLYLINE entities of an ASCII DXF. Minimal: enough to check
/// what [`to_dxf`] writes and what common CAD tools write for outlines.
pub fn read_dxf_polylines(text: &str) -> Result<Vec<DxfPolyline>, String> {
    let lines: Vec<&str> = text.lines().map(|l| l.trim()).collect();
    if lines.len() % 2 != 0 {
        return Err("DXF: odd number of lines".into());
    }
    let mut pairs = Vec::with_capacity(lines.len() / 2);
    for (k, c) in lines.chunks(2).enumerate() {
        let code: i32 = c[0].parse().map_err(|_| {
            format!(
                "DXF line {}: group code {:?} is not an integer",
                2 * k + 1,
                c[0]
            )
        })?;
        pairs.push((code, c[1]));
    }
    let num = |v: &str, at: usize| -> Result<f64, String> {
        v.parse::<f64>()
            .map_err(|_| format!("DXF pair {at}: {v:?} is not a number"))
    };
    let mut out: Vec<DxfPolyline> = Vec::new();
    let mut i = 0;
    while i < pairs.len() {
        let (code, v) = pairs[i];
        if code == 0 && (v == "POLYLINE" || v == "LWPOLYLINE") {
            let lw = v == "LWPOLYLINE";
            let mut pl = DxfPolyline {
                layer: String::new(),
                closed: false,
                points: Vec::new(),
            };
            i += 1;
            // entity header (for LWPOLYLINE also the vertices)
            let mut pending_x: Option<f64> = None;
            while i < pairs.len() && pairs[i].0 != 0 {
                let (c, v) = pairs[i];
                match c {
                    8 => pl.layer = v.to_string(),
                    70 => pl.closed = v.parse::<i32>().map(|f| f & 1 == 1).unwrap_or(false),
                    10 if lw => pending_x = Some(num(v, i)?),
                    20 if lw => {
                        let x = pending_x
                            .take()
                            .ok_or(format!("DXF pair {i}: y before x"))?;
                        pl.points.push([x, num(v, i)?]);
                    }
                    _ => {}
                }
                i += 1;
            }
            if !lw {
                while i < pairs.len() && pairs[i] == (0, "VERTEX") {
                    i += 1;
                    let (mut x, mut y) = (None, None);
                    while i < pairs.len() && pairs[i].0 != 0 {
                        match pairs[i].0 {
                            10 => x = Some(num(pairs[i].1, i)?),
                            20 => y = Some(num(pairs[i].1, i)?),
                            _ => {}
                        }
                        i += 1;
                    }
                    match (x, y) {
                        (Some(x), Some(y)) => pl.points.push([x, y]),
                        _ => return Err(format!("DXF pair {i}: VERTEX without 10/20")),
                    }
                }
                if i < pairs.len() && pairs[i] == (0, "SEQEND") {
                    i += 1;
                } else {
                    return Err(format!("DXF pair {i}: POLYLINE without SEQEND"));
                }
            }
            out.push(pl);
            continue;
        }
        i += 1;
    }
    Ok(out)
}
