//! Rasterise an SVG (a pattern drawing) to PNG with resvg, to look at what a user sees:
//! `cargo run --release --example render_svg -- IN.svg OUT.png [WIDTH_PX]`.

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: render_svg IN.svg OUT.png [WIDTH_PX]");
        std::process::exit(2);
    }
    let width: u32 = args.get(2).and_then(|w| w.parse().ok()).unwrap_or(1600);
    let data = std::fs::read(&args[0]).expect("read the SVG");
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    let tree = resvg::usvg::Tree::from_data(&data, &opt).expect("parse the SVG");
    let size = tree.size();
    let scale = width as f32 / size.width();
    let height = (size.height() * scale).ceil().max(1.0) as u32;
    let mut pixmap = resvg::tiny_skia::Pixmap::new(width, height).expect("pixmap");
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    pixmap.save_png(&args[1]).expect("write the PNG");
}
