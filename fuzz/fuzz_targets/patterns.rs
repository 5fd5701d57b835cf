//! The pattern exporters on what a user can make them draw: an arbitrary small OBJ mesh,
//! flattened with few iterations, written as JSON, SVG and DXF, and the DXF read back.
#![no_main]

use flatmesh::algorithms::{flatten, Silent};
use flatmesh::io::{self, Format, Limits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = Limits {
        max_triangles: 2_000,
    };
    let Ok((mesh, _)) = io::load_limited(data, Format::Obj, &limits) else {
        return;
    };
    let params = flatten::Params {
        max_iterations: 20,
        ..flatten::Params::default()
    };
    let Ok(out) = flatten::run(&mesh, &params, &Silent::default()) else {
        return;
    };
    if let Some(p) = &out.patterns {
        let _ = io::pattern::to_json(p);
        let _ = io::pattern::to_svg(p);
        let dxf = io::pattern::to_dxf(p);
        io::pattern::read_dxf_polylines(&dxf).expect("our own DXF reads back");
        let plain = io::pattern::to_dxf_plain(p);
        io::pattern::read_dxf_polylines(&plain).expect("our own plain DXF reads back");
    }
});
