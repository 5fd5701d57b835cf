//! glTF reader and writer: round trips (write, read back, same geometry and patches), the
//! binary layout rules of the glTF 2.0 spec checked byte by byte, the reader's features
//! (transforms, index widths, non-indexed primitives, welding across primitives) against
//! hand-built documents, refusals of bad and hostile input, and mutation fuzzing.

use base64::Engine;
use flatmesh::geometry;
use flatmesh::io::{self, gltf, Format, ReadError};
use flatmesh::mesh::{Mesh, RawMesh};
use serde_json::{json, Value};

fn grid(nx: usize, ny: usize, z: impl Fn(f64, f64) -> f64) -> RawMesh {
    let mut positions = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (i as f64 / nx as f64, j as f64 / ny as f64);
            positions.push([x, y, z(x, y)]);
        }
    }
    let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
    let mut triangles = Vec::new();
    let mut face_patch = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            let p = u32::from(i >= nx / 2);
            face_patch.extend([p, p]);
        }
    }
    RawMesh {
        positions,
        triangles,
        face_patch,
        patch_names: vec!["left".into(), "right panel".into()],
        uv: None,
    }
}

fn two_patch_mesh() -> Mesh {
    Mesh::new(grid(8, 6, |x, y| 0.3 * (3.0 * x).sin() * y * y))
        .unwrap()
        .0
}

/// Check that `back` is `mesh` with positions rounded to f32, same triangles and patches.
/// A mesh whose vertices have several texture coordinates (UV seams) is written one patch at
/// a time and welded back, so its vertices come back renumbered: then the check is through the
/// faces (grouped by patch, in order), which must map vertices one to one, with the same
/// positions and the same texture coordinates (f32).
fn assert_same(mesh: &Mesh, back: &Mesh, what: &str) {
    if let Some(uv) = mesh.uv() {
        assert_same_through_faces(mesh, uv, back, what);
        return;
    }
    assert_eq!(
        back.num_vertices(),
        mesh.num_vertices(),
        "{what}: vertex count"
    );
    for (i, (p, q)) in mesh.positions().iter().zip(back.positions()).enumerate() {
        for k in 0..3 {
            assert_eq!(
                q[k],
                f64::from(p[k] as f32),
                "{what}: vertex {i} coordinate {k}"
            );
        }
    }
    // Faces come back grouped by patch (one primitive per patch), each triangle with the
    // same corners in the same rotation, in the same patch.
    let faces = |m: &Mesh| {
        let mut f: Vec<([u32; 3], u32)> = m
            .triangles()
            .iter()
            .copied()
            .zip(m.face_patch().iter().copied())
            .collect();
        f.sort_by_key(|&(t, p)| (p, t));
        f
    };
    assert_eq!(
        faces(back),
        faces(mesh),
        "{what}: triangles and their patches"
    );
    assert_eq!(
        back.patch_names(),
        mesh.patch_names(),
        "{what}: patch names"
    );
}

fn assert_same_through_faces(mesh: &Mesh, uv: &flatmesh::mesh::UvLayer, back: &Mesh, what: &str) {
    assert_eq!(
        back.num_vertices(),
        mesh.num_vertices(),
        "{what}: vertex count"
    );
    assert_eq!(back.num_faces(), mesh.num_faces(), "{what}: face count");
    assert_eq!(
        back.patch_names(),
        mesh.patch_names(),
        "{what}: patch names"
    );
    let back_uv = back.uv().expect("texture coordinates read back");
    let mut order: Vec<usize> = (0..mesh.num_faces()).collect();
    order.sort_by_key(|&f| mesh.face_patch()[f]);
    let mut map = vec![u32::MAX; mesh.num_vertices()];
    for (g, &f) in order.iter().enumerate() {
        assert_eq!(
            back.face_patch()[g],
            mesh.face_patch()[f],
            "{what}: face {f} patch"
        );
        for k in 0..3 {
            let (v, w) = (mesh.triangles()[f][k], back.triangles()[g][k]);
            assert!(
                map[v as usize] == u32::MAX || map[v as usize] == w,
                "{what}: vertex {v} split"
            );
            map[v as usize] = w;
            let (p, q) = (mesh.positions()[v as usize], back.positions()[w as usize]);
            for c in 0..3 {
                assert_eq!(
                    q[c],
                    f64::from(p[c] as f32),
                    "{what}: vertex {v} coordinate {c}"
                );
            }
            let a = uv.coords[uv.triangles[f][k] as usize];
            let b = back_uv.coords[back_uv.triangles[g][k] as usize];
            assert_eq!(
                b[0],
                f64::from(a[0] as f32),
                "{what}: face {f} corner {k} u"
            );
            assert!(
                (b[1] - a[1]).abs() <= 1e-6 * (1.0 + a[1].abs()),
                "{what}: face {f} corner {k} v"
            );
        }
    }
}

#[test]
fn round_trip_glb_and_gltf_keeps_geometry_and_patches() {
    let mesh = two_patch_mesh();
    let varpi = geometry::flattenability(&mesh, &geometry::angle_sums(&mesh));
    for (bytes, format) in [
        (gltf::write_glb(&mesh, Some(&varpi)), Format::Glb),
        (gltf::write_glb(&mesh, None), Format::Glb),
        (gltf::write_gltf(&mesh, Some(&varpi)), Format::Gltf),
    ] {
        assert_eq!(Format::sniff(&bytes), Some(format));
        let (back, warnings) = io::load(&bytes, format).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_same(&mesh, &back, &format!("{format:?}"));
        // Topology survives: the seam between the two panels is still shared.
        assert_eq!(back.conn().shared_vertices(), mesh.conn().shared_vertices());
    }
}

/// A parsed GLB: the JSON and the binary chunk, after checking the container rules.
fn parse_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[0..4], b"glTF", "magic");
    assert_eq!(u32_at(4), 2, "container version");
    assert_eq!(u32_at(8), bytes.len(), "header length equals file length");
    let json_len = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON", "first chunk is JSON");
    assert_eq!(json_len % 4, 0, "JSON chunk length is 4-aligned");
    let json_bytes = &bytes[20..20 + json_len];
    let trimmed = json_bytes.iter().rposition(|&b| b != b' ').unwrap() + 1;
    assert!(json_len - trimmed < 4, "JSON padded with at most 3 spaces");
    let root: Value = serde_json::from_slice(&json_bytes[..trimmed]).unwrap();
    let bin_at = 20 + json_len;
    let bin_len = u32_at(bin_at);
    assert_eq!(
        &bytes[bin_at + 4..bin_at + 8],
        b"BIN\0",
        "second chunk is BIN"
    );
    assert_eq!(bin_len % 4, 0, "BIN chunk length is 4-aligned");
    assert_eq!(bin_at + 8 + bin_len, bytes.len(), "no trailing bytes");
    (root, bytes[bin_at + 8..].to_vec())
}

fn as_usize(v: &Value) -> usize {
    v.as_u64().expect("integer") as usize
}

/// Read accessor `a` as f32 components (the test's own reader, independent of the crate's).
fn accessor_f32(root: &Value, bin: &[u8], a: usize) -> (Vec<f32>, usize) {
    let acc = &root["accessors"][a];
    let view = &root["bufferViews"][as_usize(&acc["bufferView"])];
    let comps = match acc["type"].as_str().unwrap() {
        "SCALAR" => 1,
        "VEC3" => 3,
        t => panic!("unexpected type {t}"),
    };
    assert_eq!(acc["componentType"], 5126);
    let start = as_usize(&view["byteOffset"]) + acc.get("byteOffset").map_or(0, as_usize);
    let count = as_usize(&acc["count"]);
    let vals = (0..count * comps)
        .map(|i| f32::from_le_bytes(bin[start + 4 * i..start + 4 * i + 4].try_into().unwrap()))
        .collect();
    (vals, comps)
}

#[test]
fn glb_follows_the_layout_rules() {
    let mesh = two_patch_mesh();
    let varpi = geometry::flattenability(&mesh, &geometry::angle_sums(&mesh));
    let bytes = gltf::write_glb(&mesh, Some(&varpi));
    let (root, bin) = parse_glb(&bytes);
    assert_eq!(root["asset"]["version"], "2.0");
    let buffer_len = as_usize(&root["buffers"][0]["byteLength"]);
    assert!(
        buffer_len <= bin.len() && bin.len() - buffer_len < 4,
        "buffer length"
    );
    assert!(
        root["buffers"][0].get("uri").is_none(),
        "GLB buffer has no uri"
    );

    // Buffer views inside the buffer, 4-aligned (all our components are 4 bytes).
    for (i, v) in root["bufferViews"].as_array().unwrap().iter().enumerate() {
        let (off, len) = (as_usize(&v["byteOffset"]), as_usize(&v["byteLength"]));
        assert_eq!(off % 4, 0, "bufferViews[{i}] offset alignment");
        assert!(off + len <= buffer_len, "bufferViews[{i}] inside buffer");
        assert!(matches!(v["target"].as_u64(), Some(34962 | 34963)));
    }
    // Accessors fit their views.
    for (i, a) in root["accessors"].as_array().unwrap().iter().enumerate() {
        let view = &root["bufferViews"][as_usize(&a["bufferView"])];
        let comps = if a["type"] == "VEC3" { 3 } else { 1 };
        let need = a.get("byteOffset").map_or(0, as_usize) + 4 * comps * as_usize(&a["count"]);
        assert!(need <= as_usize(&view["byteLength"]), "accessors[{i}] fits");
        assert!(matches!(a["componentType"].as_u64(), Some(5126 | 5125)));
    }

    let prims = root["meshes"][0]["primitives"].as_array().unwrap();
    assert_eq!(prims.len(), mesh.num_patches(), "one primitive per patch");
    let attrs = &prims[0]["attributes"];
    // POSITION min/max are exactly the extremes of the stored values.
    let pos_acc = as_usize(&attrs["POSITION"]);
    let (pos, _) = accessor_f32(&root, &bin, pos_acc);
    for k in 0..3 {
        let vals = pos.iter().skip(k).step_by(3);
        let min = vals.clone().copied().fold(f32::INFINITY, f32::min);
        let max = vals.copied().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(
            root["accessors"][pos_acc]["min"][k].as_f64().unwrap(),
            f64::from(min)
        );
        assert_eq!(
            root["accessors"][pos_acc]["max"][k].as_f64().unwrap(),
            f64::from(max)
        );
    }
    // Normals are unit vectors (the validator allows 5e-4).
    let (nrm, _) = accessor_f32(&root, &bin, as_usize(&attrs["NORMAL"]));
    for n in nrm.chunks(3) {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((l - 1.0).abs() < 1e-6, "normal length {l}");
    }
    // _FLATTENABILITY carries ϖ; COLOR_0 is the heat map, in [0, 1].
    let (f, _) = accessor_f32(&root, &bin, as_usize(&attrs["_FLATTENABILITY"]));
    for (i, (&a, &b)) in f.iter().zip(&varpi).enumerate() {
        assert_eq!(a, b as f32, "ϖ of vertex {i}");
    }
    // The heat map's range comes from the data: the 1st and 99th percentiles of interior
    // ϖ (recomputed here), at least a decade wide and never below the developable tolerance.
    let mut interior: Vec<f64> = (0..mesh.num_vertices())
        .filter(|&i| mesh.conn().is_interior(i as u32))
        .map(|i| varpi[i])
        .collect();
    interior.sort_by(f64::total_cmp);
    let pct = |q: f64| interior[((interior.len() - 1) as f64 * q).round() as usize];
    let lo = pct(0.01).max(gltf::HEATMAP_MIN);
    let hi = pct(0.99).max(10.0 * lo);
    let scale = &root["asset"]["extras"]["flatmesh"]["heatmap"];
    assert_eq!(scale["min"].as_f64(), Some(lo));
    assert_eq!(scale["max"].as_f64(), Some(hi));
    let (c, _) = accessor_f32(&root, &bin, as_usize(&attrs["COLOR_0"]));
    assert!(c.iter().all(|x| (0.0..=1.0).contains(x)));
    for (i, rgb) in c.chunks(3).enumerate() {
        let expect = if mesh.conn().is_interior(i as u32) {
            gltf::heat_color_in(varpi[i], (lo, hi))
        } else {
            [0.6, 0.6, 0.6]
        };
        assert_eq!(rgb, expect, "colour of vertex {i}");
    }
    // A material viewers render as intended: not metallic, both sides drawn.
    let mat = &root["materials"][0];
    assert_eq!(mat["doubleSided"], true);
    assert_eq!(
        mat["pbrMetallicRoughness"]["metallicFactor"].as_f64(),
        Some(0.0)
    );
    assert!(prims.iter().all(|p| p["material"] == 0));
    // Indices in range, u32, and every patch's faces present.
    for (p, prim) in prims.iter().enumerate() {
        let acc = &root["accessors"][as_usize(&prim["indices"])];
        let view = &root["bufferViews"][as_usize(&acc["bufferView"])];
        let start = as_usize(&view["byteOffset"]);
        let count = as_usize(&acc["count"]);
        let idx: Vec<u32> = (0..count)
            .map(|i| u32::from_le_bytes(bin[start + 4 * i..start + 4 * i + 4].try_into().unwrap()))
            .collect();
        assert!(idx.iter().all(|&i| (i as usize) < mesh.num_vertices()));
        let expected: Vec<u32> = mesh
            .triangles()
            .iter()
            .zip(mesh.face_patch())
            .filter(|(_, &fp)| fp as usize == p)
            .flat_map(|(t, _)| *t)
            .collect();
        assert_eq!(idx, expected, "primitive {p} indices");
        assert_eq!(prim["extras"]["patch"], mesh.patch_names()[p].as_str());
    }
}

/// The fixed scale, on request, is the same for every mesh; the data scale spreads a
/// typical garment's ϖ (1e-3–0.3 rad) over the colours instead of showing it in one.
#[test]
fn heat_map_scale_from_the_data_or_fixed() {
    let spread: Vec<f64> = (0..100)
        .map(|k| 1e-3 * 300f64.powf(k as f64 / 99.0))
        .collect();
    assert_eq!(
        gltf::heatmap_range(gltf::HeatmapScale::Fixed, &spread),
        (gltf::HEATMAP_MIN, gltf::HEATMAP_MAX)
    );
    let range = gltf::heatmap_range(gltf::HeatmapScale::Data, &spread);
    let colours = |r: (f64, f64)| {
        spread
            .iter()
            .map(|&v| gltf::heat_color_in(v, r).map(|x| (x * 4.0).round() as i32))
            .collect::<std::collections::BTreeSet<_>>()
            .len()
    };
    assert!(colours(range) > 2 * colours((gltf::HEATMAP_MIN, gltf::HEATMAP_MAX)));
    // A developable mesh: all blue, never a range narrower than a decade.
    let flat = vec![0.0; 10];
    let (lo, hi) = gltf::heatmap_range(gltf::HeatmapScale::Data, &flat);
    assert_eq!(lo, gltf::HEATMAP_MIN);
    assert!(hi >= 10.0 * lo);
    assert_eq!(gltf::heat_color_in(0.0, (lo, hi)), [0.0, 0.0, 1.0]);
    // Written with the fixed scale, the extras say so.
    let mesh = flatmesh::io::load(
        &std::fs::read("fixtures/cylinder.obj").unwrap(),
        flatmesh::io::Format::Obj,
    )
    .unwrap()
    .0;
    let varpi = vec![0.5; mesh.num_vertices()];
    let glb = gltf::write_glb_scaled(&mesh, Some(&varpi), &[], gltf::HeatmapScale::Fixed);
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let root: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let h = &root["asset"]["extras"]["flatmesh"]["heatmap"];
    assert_eq!(h["range"], "fixed");
    assert_eq!(h["max"].as_f64(), Some(gltf::HEATMAP_MAX));
}

#[test]
fn heat_map_runs_blue_to_red_on_a_log_scale() {
    assert_eq!(gltf::heat_color(0.0), [0.0, 0.0, 1.0]);
    assert_eq!(gltf::heat_color(gltf::HEATMAP_MIN), [0.0, 0.0, 1.0]);
    assert_eq!(gltf::heat_color(gltf::HEATMAP_MAX), [1.0, 0.0, 0.0]);
    assert_eq!(gltf::heat_color(10.0), [1.0, 0.0, 0.0]);
    // Geometric midpoint of the scale (1e-3 rad) is the middle stop, green.
    assert_eq!(gltf::heat_color(1e-3), [0.0, 1.0, 0.0]);
    // Position along the path blue → cyan → green → yellow → red grows with ϖ.
    let along = |c: [f32; 3]| -> f32 {
        let [r, g, b] = c;
        if b > 0.0 && g < 1.0 {
            g
        } else if b > 0.0 {
            2.0 - b
        } else if r < 1.0 {
            2.0 + r
        } else {
            4.0 - g
        }
    };
    let mut last = -1.0;
    for k in 0..=120 {
        let s = along(gltf::heat_color(10f64.powf(-7.0 + k as f64 * 0.06)));
        assert!(s >= last - 1e-6, "not monotone at step {k}");
        last = s;
    }
    assert_eq!(last, 4.0);
}

/// Build a `.gltf` document with the given accessor data packed into one embedded buffer.
struct Doc {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Doc {
    fn new() -> Self {
        Doc {
            bin: Vec::new(),
            views: Vec::new(),
            accessors: Vec::new(),
        }
    }
    fn add(&mut self, bytes: &[u8], component: u32, count: usize, ty: &str) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        self.views
            .push(json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()}));
        self.bin.extend_from_slice(bytes);
        self.accessors.push(json!({"bufferView": self.views.len() - 1, "componentType": component, "count": count, "type": ty}));
        self.accessors.len() - 1
    }
    fn positions(&mut self, pts: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = pts.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let a = self.add(&bytes, 5126, pts.len(), "VEC3");
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in pts {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        self.accessors[a]["min"] = json!(min);
        self.accessors[a]["max"] = json!(max);
        a
    }
    fn indices_u8(&mut self, idx: &[u8]) -> usize {
        self.add(idx, 5121, idx.len(), "SCALAR")
    }
    fn indices_u16(&mut self, idx: &[u16]) -> usize {
        let bytes: Vec<u8> = idx.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.add(&bytes, 5123, idx.len(), "SCALAR")
    }
    fn indices_u32(&mut self, idx: &[u32]) -> usize {
        let bytes: Vec<u8> = idx.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.add(&bytes, 5125, idx.len(), "SCALAR")
    }
    fn finish(&self, meshes: Value, nodes: Value) -> Value {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": (0..nodes.as_array().unwrap().len()).filter(|i| {
                // Roots: nodes nobody lists as a child.
                !nodes.as_array().unwrap().iter().any(|n| n["children"].as_array().is_some_and(|c| c.contains(&json!(i))))
            }).collect::<Vec<_>>()}],
            "nodes": nodes,
            "meshes": meshes,
            "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [{"byteLength": self.bin.len(), "uri": uri}],
        })
    }
}

fn read_doc(doc: &Value) -> Result<(Mesh, Vec<flatmesh::mesh::Warning>), ReadError> {
    io::load(&serde_json::to_vec(doc).unwrap(), Format::Gltf)
}

/// Unit square in the z = 0 plane as two triangles over four vertices.
const SQUARE: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];

#[test]
fn node_transforms_are_applied_in_order() {
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let meshes =
        json!([{"name": "sq", "primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]);
    // Parent: translate (10, 0, 0) and scale 2; child: rotate 90° about z (quaternion),
    // translate (0, 0, 5). World = Parent · Child.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let nodes = json!([
        {"translation": [10.0, 0.0, 0.0], "scale": [2.0, 2.0, 2.0], "children": [1]},
        {"rotation": [0.0, 0.0, s, s], "translation": [0.0, 0.0, 5.0], "mesh": 0}
    ]);
    let (mesh, warnings) = read_doc(&d.finish(meshes, nodes)).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    for (i, p) in SQUARE.iter().enumerate() {
        // Rz(90°)(x, y, z) = (−y, x, z); + (0,0,5); ×2; + (10,0,0).
        let expect = [
            10.0 + 2.0 * -f64::from(p[1]),
            2.0 * f64::from(p[0]),
            2.0 * (f64::from(p[2]) + 5.0),
        ];
        for k in 0..3 {
            assert!(
                (mesh.positions()[i][k] - expect[k]).abs() < 1e-6,
                "vertex {i}: {:?} vs {expect:?}",
                mesh.positions()[i]
            );
        }
    }
    assert_eq!(mesh.patch_names(), ["sq"]);
}

#[test]
fn matrix_transform_and_mirroring_keep_outward_orientation() {
    // A closed tetrahedron, outward-oriented; a mirroring matrix (x → −x) must flip the
    // winding so that the signed volume stays positive.
    let pts = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let tris: [u8; 12] = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];
    let signed_volume = |m: &Mesh| -> f64 {
        m.triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions()[i as usize]);
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    };
    for (matrix, volume) in [
        (
            json!([1.0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
            1.0 / 6.0,
        ),
        (
            json!([-1.0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 3, 0, 0, 1]),
            1.0 / 6.0,
        ),
        (
            json!([2.0, 0, 0, 0, 0, 2, 0, 0, 0, 0, -2, 0, 0, 0, 0, 1]),
            8.0 / 6.0,
        ),
    ] {
        let mut d = Doc::new();
        let pos = d.positions(&pts);
        let idx = d.indices_u8(&tris);
        let meshes = json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]);
        let nodes = json!([{"matrix": matrix, "mesh": 0}]);
        let (mesh, _) = read_doc(&d.finish(meshes, nodes)).unwrap();
        assert!(
            (signed_volume(&mesh) - volume).abs() < 1e-9,
            "volume {} vs {volume}",
            signed_volume(&mesh)
        );
    }
}

#[test]
fn index_widths_and_non_indexed_primitives() {
    let tri = [0u32, 1, 2, 0, 2, 3];
    for width in [8, 16, 32, 0] {
        let mut d = Doc::new();
        let prim = if width == 0 {
            // Non-indexed: six corners; bit-identical corners are one vertex.
            let corners: Vec<[f32; 3]> = tri.iter().map(|&i| SQUARE[i as usize]).collect();
            let pos = d.positions(&corners);
            json!({"attributes": {"POSITION": pos}})
        } else {
            let pos = d.positions(&SQUARE);
            let idx = match width {
                8 => d.indices_u8(&tri.map(|i| i as u8)),
                16 => d.indices_u16(&tri.map(|i| i as u16)),
                _ => d.indices_u32(&tri),
            };
            json!({"attributes": {"POSITION": pos}, "indices": idx, "mode": 4})
        };
        let doc = d.finish(json!([{"primitives": [prim]}]), json!([{"mesh": 0}]));
        let (mesh, warnings) = read_doc(&doc).unwrap();
        assert!(warnings.is_empty(), "width {width}: {warnings:?}");
        assert_eq!(mesh.num_vertices(), 4, "width {width}");
        assert_eq!(mesh.num_faces(), 2, "width {width}");
        assert_eq!(
            mesh.conn().edges().len(),
            5,
            "width {width}: the diagonal is shared"
        );
    }
}

/// Two primitives (own accessors) meeting along x = 1; the right one optionally shifted.
fn two_panels(shift: f32, translate_right: Option<f32>) -> Value {
    let mut d = Doc::new();
    let left: Vec<[f32; 3]> = (0..3)
        .flat_map(|j| (0..3).map(move |i| [i as f32 * 0.5, j as f32 * 0.5, 0.0]))
        .collect();
    let right: Vec<[f32; 3]> = left
        .iter()
        .map(|p| [p[0] + 1.0 + shift, p[1], 0.0])
        .collect();
    let mut idx = Vec::new();
    for j in 0..2u16 {
        for i in 0..2u16 {
            let v = j * 3 + i;
            idx.extend([v, v + 1, v + 4, v, v + 4, v + 3]);
        }
    }
    let pl = d.positions(&left);
    let il = d.indices_u16(&idx);
    let right_local: Vec<[f32; 3]> = match translate_right {
        Some(t) => right.iter().map(|p| [p[0] - t, p[1], p[2]]).collect(),
        None => right,
    };
    let pr = d.positions(&right_local);
    let ir = d.indices_u16(&idx);
    match translate_right {
        None => d.finish(
            json!([{"name": "garment", "primitives": [
                {"attributes": {"POSITION": pl}, "indices": il, "extras": {"patch": "front"}},
                {"attributes": {"POSITION": pr}, "indices": ir, "extras": {"patch": "back"}}]}]),
            json!([{"mesh": 0}]),
        ),
        Some(t) => d.finish(
            json!([{"name": "L", "primitives": [{"attributes": {"POSITION": pl}, "indices": il}]},
                   {"name": "R", "primitives": [{"attributes": {"POSITION": pr}, "indices": ir}]}]),
            json!([{"mesh": 0}, {"mesh": 1, "translation": [t, 0.0, 0.0]}]),
        ),
    }
}

#[test]
fn coincident_borders_of_different_primitives_are_welded() {
    // Exactly coincident, and within tolerance after a node transform: 18 − 3 vertices, the
    // middle seam vertex becomes a seam (shared) vertex, the patches are one component.
    for doc in [
        two_panels(0.0, None),
        two_panels(0.0, Some(0.7)),
        two_panels(1e-7, None),
    ] {
        let (mesh, warnings) = read_doc(&doc).unwrap();
        assert_eq!(mesh.num_vertices(), 15);
        assert_eq!(mesh.conn().shared_vertices().len(), 3);
        assert_eq!(mesh.conn().components(mesh.num_faces()), 1);
        assert!(warnings.iter().any(|w| w.code == "vertices_welded"));
        assert_eq!(mesh.num_patches(), 2);
    }
    let (mesh, _) = read_doc(&two_panels(0.0, None)).unwrap();
    assert_eq!(mesh.patch_names(), ["front", "back"]);
    // Well apart (1e-3 of a 2.5-wide box): not welded.
    let (mesh, warnings) = read_doc(&two_panels(1e-3, None)).unwrap();
    assert_eq!(mesh.num_vertices(), 18);
    assert_eq!(mesh.conn().components(mesh.num_faces()), 2);
    assert!(warnings.is_empty());
}

#[test]
fn an_indexed_file_keeps_its_own_cuts() {
    // One accessor with two coincident vertices along a cut: the file says they are distinct,
    // and they stay distinct (welding is only across primitives' vertex spaces).
    let pts: [[f32; 3]; 6] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let mut d = Doc::new();
    let pos = d.positions(&pts);
    let i0 = d.indices_u8(&[0, 1, 2]);
    let i1 = d.indices_u8(&[3, 4, 5]);
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": i0},
                               {"attributes": {"POSITION": pos}, "indices": i1}]}]),
        json!([{"mesh": 0}]),
    );
    let (mesh, _) = read_doc(&doc).unwrap();
    assert_eq!(mesh.num_vertices(), 6);
    assert_eq!(mesh.conn().components(mesh.num_faces()), 2);
    assert_eq!(mesh.patch_names(), ["mesh0/0", "mesh0/1"]);
}

#[test]
fn vertices_split_for_flat_shading_are_kept_with_a_warning() {
    // A cube exported flat-shaded: 24 vertices (4 per face), 12 triangles, the layout of the
    // Khronos "Box" sample. The file's connectivity is six separate squares.
    let mut pts = Vec::new();
    let mut idx: Vec<u8> = Vec::new();
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            let base = pts.len() as u8;
            for (u, v) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                let mut p = [0.0f32; 3];
                p[axis] = side;
                p[(axis + 1) % 3] = u;
                p[(axis + 2) % 3] = v;
                pts.push(p);
            }
            if side == 0.0 {
                idx.extend([base, base + 2, base + 1, base, base + 3, base + 2]);
            } else {
                idx.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            }
        }
    }
    let mut d = Doc::new();
    let pos = d.positions(&pts);
    let i = d.indices_u8(&idx);
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": i}]}]),
        json!([{"mesh": 0}]),
    );
    let (mesh, warnings) = read_doc(&doc).unwrap();
    assert_eq!(mesh.num_vertices(), 24);
    assert_eq!(mesh.conn().components(mesh.num_faces()), 6);
    let w = warnings
        .iter()
        .find(|w| w.code == "coincident_vertices_kept")
        .expect("a warning about split vertices");
    // 8 corners, each present 3 times: 16 extra copies.
    assert!(w.message.contains("16 vertices"), "{}", w.message);
}

#[test]
fn other_modes_are_skipped_with_a_warning() {
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u8(&[0, 1, 2, 0, 2, 3]);
    let lines = d.indices_u8(&[0, 1, 1, 2]);
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx},
                               {"attributes": {"POSITION": pos}, "indices": lines, "mode": 1}]}]),
        json!([{"mesh": 0}]),
    );
    let (mesh, warnings) = read_doc(&doc).unwrap();
    assert_eq!(mesh.num_faces(), 2);
    assert!(warnings
        .iter()
        .any(|w| w.code == "primitive_skipped" && w.message.contains("primitives[1]")));
}

fn expect_err(doc: &Value, needle: &str) {
    match read_doc(doc) {
        Ok(_) => panic!("accepted; expected an error containing `{needle}`"),
        Err(e) => assert!(
            e.to_string().contains(needle),
            "`{e}` does not mention `{needle}`"
        ),
    }
}

fn square_doc() -> (Doc, usize, usize) {
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u8(&[0, 1, 2, 0, 2, 3]);
    (d, pos, idx)
}

fn square_value() -> Value {
    let (d, pos, idx) = square_doc();
    d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]),
        json!([{"mesh": 0}]),
    )
}

#[test]
fn external_and_file_uris_are_never_followed() {
    for uri in [
        "mesh.bin",
        "file:///etc/passwd",
        "https://example.com/a.bin",
        "../../secret.bin",
    ] {
        let mut doc = square_value();
        doc["buffers"][0]["uri"] = json!(uri);
        expect_err(&doc, "is not followed");
    }
    let mut doc = square_value();
    doc["buffers"][0]["uri"] = json!("data:application/octet-stream,plain");
    expect_err(&doc, "not base64");
}

#[test]
fn hostile_accessors_are_refused_before_allocation() {
    // An accessor claiming 2³² − 1 elements in a 48-byte view.
    let mut doc = square_value();
    doc["accessors"][0]["count"] = json!(u32::MAX);
    expect_err(&doc, "do not fit");
    // A view reaching past its buffer.
    let mut doc = square_value();
    doc["bufferViews"][0]["byteLength"] = json!(1u64 << 40);
    expect_err(&doc, "glTF");
    // A buffer longer than its data.
    let mut doc = square_value();
    doc["buffers"][0]["byteLength"] = json!(1000);
    expect_err(&doc, "only");
    // An index past the primitive's vertices.
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u8(&[0, 1, 2, 0, 2, 9]);
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]),
        json!([{"mesh": 0}]),
    );
    expect_err(&doc, "uses vertex 9");
    // Indices not a multiple of three.
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u8(&[0, 1, 2, 0]);
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]),
        json!([{"mesh": 0}]),
    );
    expect_err(&doc, "multiple of 3");
    // Float indices; integer positions.
    let mut doc = square_value();
    doc["accessors"][1]["componentType"] = json!(5126);
    expect_err(&doc, "glTF");
    let mut doc = square_value();
    doc["accessors"][0]["componentType"] = json!(5123);
    expect_err(&doc, "POSITION must be VEC3 of FLOAT");
    // A NaN coordinate.
    let (mut d, pos, idx) = square_doc();
    d.bin[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    let doc = d.finish(
        json!([{"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]),
        json!([{"mesh": 0}]),
    );
    expect_err(&doc, "non-finite");
}

#[test]
fn bad_scene_graphs_and_empty_scenes_are_refused() {
    // A node that is its own descendant.
    let mut doc = square_value();
    doc["nodes"] = json!([{"mesh": 0, "children": [1]}, {"children": [0]}]);
    doc["scenes"] = json!([{"nodes": [0]}]);
    assert!(read_doc(&doc).is_err());
    // Nothing to read.
    let mut doc = square_value();
    doc["nodes"] = json!([{}]);
    expect_err(&doc, "no triangle primitive");
    // Not JSON / not glTF.
    assert!(io::load(b"{\"asset\": 5}", Format::Gltf).is_err());
    assert!(io::load(b"glTF\x02\0\0\0\x10\0\0\0", Format::Glb).is_err());
    assert!(io::load(b"", Format::Glb).is_err());
}

/// splitmix64, for reproducible mutations.
fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[test]
fn mutated_files_never_panic() {
    let mesh = two_patch_mesh();
    let varpi = geometry::flattenability(&mesh, &geometry::angle_sums(&mesh));
    let glb = gltf::write_glb(&mesh, Some(&varpi));
    let text = gltf::write_gltf(&mesh, None);
    let mut state = 7u64;
    let mut accepted = 0;
    for round in 0..3000 {
        let (mut bytes, format) = if round % 2 == 0 {
            (glb.clone(), Format::Glb)
        } else {
            (text.clone(), Format::Gltf)
        };
        match next(&mut state) % 4 {
            // Flip a few bytes (the GLB header and JSON are the interesting part).
            0 | 1 => {
                for _ in 0..1 + next(&mut state) % 4 {
                    let limit = if round % 3 == 0 {
                        bytes.len()
                    } else {
                        bytes.len().min(2000)
                    };
                    let at = (next(&mut state) as usize) % limit;
                    bytes[at] = next(&mut state) as u8;
                }
            }
            // Truncate.
            2 => bytes.truncate((next(&mut state) as usize) % bytes.len()),
            // Replace a number in the JSON with a large or negative one.
            _ => {
                let s = String::from_utf8_lossy(&bytes).into_owned();
                let digits: Vec<usize> = s
                    .char_indices()
                    .filter(|(_, c)| c.is_ascii_digit())
                    .map(|(i, _)| i)
                    .take(3000)
                    .collect();
                let at = digits[(next(&mut state) as usize) % digits.len()];
                let big = ["4294967295", "-1", "99999999999", "0", "65536", "3"]
                    [(next(&mut state) % 6) as usize];
                let mut t = s.clone();
                t.replace_range(at..at + 1, big);
                bytes = t.into_bytes();
            }
        }
        let result = std::panic::catch_unwind(|| io::load(&bytes, format));
        match result {
            Ok(Ok((m, _))) => {
                accepted += 1;
                assert!(m.positions().iter().flatten().all(|x| x.is_finite()));
            }
            Ok(Err(e)) => assert!(!e.to_string().is_empty()),
            Err(_) => panic!("round {round}: reading a mutated file panicked"),
        }
    }
    // Some mutations land in bytes that do not matter; most are refused.
    assert!(accepted > 0 && accepted < 3000, "accepted {accepted}");
}

#[test]
fn report_cli_writes_a_glb_carrying_the_reported_flattenability() {
    let dir = std::env::temp_dir().join(format!("flatmesh-gltf-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let obj = dir.join("m.obj");
    let glb = dir.join("m.glb");
    let mesh = two_patch_mesh();
    std::fs::write(&obj, io::obj::write(&mesh.to_raw())).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["report", "--json", "--glb"])
        .arg(&glb)
        .arg(&obj)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    let (root, bin) = parse_glb(&std::fs::read(&glb).unwrap());
    let attrs = &root["meshes"][0]["primitives"][0]["attributes"];
    let (f, _) = accessor_f32(&root, &bin, as_usize(&attrs["_FLATTENABILITY"]));
    for v in report["per_vertex"].as_array().unwrap() {
        let i = as_usize(&v["index"]);
        assert_eq!(
            f[i],
            v["flattenability"].as_f64().unwrap() as f32,
            "vertex {i}"
        );
    }
    let (back, _) = io::load_path(&glb).unwrap();
    assert_same(&mesh, &back, "CLI GLB");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_shared_mesh_round_trips_through_glb() {
    let Some(root) = flatmesh::corpus::shared_root_for_tests("glb round trip of every shared mesh")
    else {
        return;
    };
    let manifest = std::fs::read_to_string(root.join("MANIFEST.tsv")).unwrap();
    let mut checked = 0;
    for line in manifest.lines().skip(1) {
        let file = line.split('\t').next().unwrap();
        let Ok((mesh, _)) = io::load_path(&root.join(file)) else {
            continue; // refused meshes are covered by tests/engine/shared_meshes.rs
        };
        let varpi = geometry::flattenability(&mesh, &geometry::angle_sums(&mesh));
        let bytes = gltf::write_glb(&mesh, Some(&varpi));
        parse_glb(&bytes);
        let (back, _) = io::load(&bytes, Format::Glb).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_same(&mesh, &back, file);
        checked += 1;
    }
    assert!(checked >= 14, "only {checked} shared meshes loaded");
}

/// A required extension that only concerns how the model looks (a texture transform, a sheen
/// material) is ignored with a warning naming it; one that changes the geometry (Draco) is
/// still refused, by name.
#[test]
fn look_only_required_extensions_are_ignored_geometry_ones_refused() {
    let mut d = Doc::new();
    let pos = d.positions(&SQUARE);
    let idx = d.indices_u16(&[0, 1, 2, 0, 2, 3]);
    let meshes =
        json!([{"name": "sq", "primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}]);
    let mut doc = d.finish(meshes, json!([{"mesh": 0}]));
    let looks = ["KHR_texture_transform", "KHR_materials_sheen"];
    doc["extensionsUsed"] = json!(looks);
    doc["extensionsRequired"] = json!(looks);
    let (mesh, warnings) = read_doc(&doc).unwrap();
    assert_eq!(mesh.num_faces(), 2);
    let w = warnings
        .iter()
        .find(|w| w.code == "extensions_ignored")
        .expect("a warning");
    assert!(looks.iter().all(|e| w.message.contains(e)), "{}", w.message);
    doc["extensionsUsed"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
    doc["extensionsRequired"] = json!(["KHR_texture_transform", "KHR_draco_mesh_compression"]);
    let err = read_doc(&doc).unwrap_err().to_string();
    assert!(err.contains("KHR_draco_mesh_compression"), "{err}");
}
