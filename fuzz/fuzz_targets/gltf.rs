//! The GLTF reader on arbitrary bytes, within a small triangle limit: it must return a mesh
//! or an error, never panic, and a mesh it returns must validate and write back.
#![no_main]

use flatmesh::io::{self, Format, Limits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(
    // gltf-json panics on some malformed documents; the reader catches that (io::quietly)
    // and reports an error. libFuzzer's hook would abort on the caught panic: keep it for
    // every other panic only.
    init: flatmesh::io::install_quiet_panic_hook(),
    |data: &[u8]| {
    let limits = Limits {
        max_triangles: 100_000,
    };
    if let Ok((mesh, _)) = io::load_limited(data, Format::Gltf, &limits) {
        let _ = flatmesh::report::Report::compute(&mesh, &[]);
        let _ = io::gltf::write_glb(&mesh, None);
    }
    }
);
