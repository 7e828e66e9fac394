//! `sylva-bake library`: the built-in species library.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use sylva::render::capture::{CapturePipelines, PackRepr, PackView, TreeRenderer};
use sylva::render::settings::Season;
use sylva::render::GpuContext;
use sylva_bake::library::{Genus, ARCHETYPES, GENERA};
use sylva_bake::pack::{build_pack, FarBake, PackOptions};

/// What `sylva-bake library` does.
#[derive(Subcommand)]
pub(crate) enum LibraryCommand {
    /// The library's genera: family, form, leaf and bark, and how to name one
    /// in `--model` (`NAME=library:GENUS[:VARIANT]`).
    List {
        /// Print a JSON array instead of text.
        #[arg(long)]
        json: bool,
    },
    /// A contact sheet of library trees: one row per genus, its variants side
    /// on then from above (the pack the bake makes, each variant drawn by the
    /// viewer's own mesh pass).
    #[command(
        after_help = "Examples:\n  sylva-bake library render Quercus Picea --out sheet.png\n  sylva-bake library render all --variants 1 --out genera.png"
    )]
    Render {
        /// Genera or archetypes to draw (`all`: every genus; `archetypes`: every archetype).
        #[arg(required = true)]
        names: Vec<String>,
        /// The sheet to write (PNG).
        #[arg(long)]
        out: PathBuf,
        /// Variants per genus.
        #[arg(long, default_value_t = 3)]
        variants: u64,
        /// Side of each view in pixels.
        #[arg(long, default_value_t = 160)]
        size: u32,
        /// Genera side by side in a row of the sheet.
        #[arg(long, default_value_t = 1)]
        per_row: u32,
        /// Each variant in every season (leaf-on, autumn, leaf-off; evergreens
        /// alike in all three), not leaf-on only.
        #[arg(long)]
        seasons: bool,
    },
}

/// Writes `text` to stdout; a reader that stops early (`| head`) is no error.
fn print_all(text: &str) -> Result<()> {
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => Ok(r?),
    }
}

/// The entries `names` asks for, in their order.
fn entries(names: &[String]) -> Result<Vec<&'static Genus>> {
    let mut out = Vec::new();
    for n in names {
        match n.to_lowercase().as_str() {
            "all" => out.extend(GENERA.iter()),
            "archetypes" => out.extend(ARCHETYPES.iter()),
            _ => match sylva_bake::library::entry(n) {
                Some(g) => out.push(g),
                None => bail!("no genus or archetype {n:?} in the library (see `sylva-bake library list`)"),
            },
        }
    }
    Ok(out)
}

/// Renders the sheet: rows of genera, columns of variants × seasons × (side, top).
fn render_sheet(
    names: &[String],
    out: &PathBuf,
    variants: u64,
    size: u32,
    per_row: u32,
    seasons: &[Season],
) -> Result<()> {
    let list = entries(names)?;
    if !(1..=8).contains(&variants) || !(32..=1024).contains(&size) || !(1..=64).contains(&per_row) {
        bail!("--variants must be 1–8, --per-row 1–64 and --size 32–1024 px");
    }
    let gpu = GpuContext::new_headless_blocking()?;
    let pipelines = CapturePipelines::new(&gpu.device, wgpu::TextureFormat::Rgba8UnormSrgb);
    let renderer = TreeRenderer::new(&gpu);
    // The mesh and its textures only: no far tiers beyond the billboards the pack needs.
    let opts = PackOptions {
        simplified_level: false,
        clusters: false,
        far_tier: FarBake::Billboards,
        billboard_angles: 2,
        billboard_size: 32,
        ..PackOptions::default()
    };
    let columns = variants as u32 * seasons.len() as u32 * 2;
    let per_row = per_row.min(list.len() as u32);
    let rows = (list.len() as u32).div_ceil(per_row);
    let mut sheet = image::RgbaImage::from_pixel(columns * per_row * size, rows * size, image::Rgba([255; 4]));
    let quiet = |_: &str| {};
    for (row, g) in list.iter().enumerate() {
        eprintln!("library render: {} ({}/{})", g.name, row + 1, list.len());
        // One pack with the variants, as the bake makes it; each drawn as the
        // viewer draws a tree of that variant.
        let model = sylva_bake::library::model_variants(g, variants);
        let built = build_pack(g.name, &model, &opts, &gpu, &pipelines, &quiet)?;
        let pack = sylva::format::pack::decode_pack(g.name, &built.bytes)?;
        for v in 0..variants {
            renderer.set_variant(&gpu, v as u32);
            for (j, season) in seasons.iter().enumerate() {
                renderer.set_season(pack.meta.season.as_ref(), *season);
                for (k, view) in [PackView::Side, PackView::Top].into_iter().enumerate() {
                    let rgba = renderer
                        .render_pack(&gpu, &pack, PackRepr::Mesh(0), view, [size, size], [0.62, 0.74, 0.86, 1.0])
                        .context("the library pack has no mesh")?;
                    let tile = image::RgbaImage::from_raw(size, size, rgba).context("a view of the wrong size")?;
                    let (block, line) = (row as u32 % per_row, row as u32 / per_row);
                    let column = (v as u32 * seasons.len() as u32 + j as u32) * 2 + k as u32;
                    let x = (block * columns + column) * size;
                    image::imageops::replace(&mut sheet, &tile, i64::from(x), i64::from(line * size));
                }
            }
        }
    }
    sheet.save(out).with_context(|| format!("cannot write {}", out.display()))?;
    let rows: Vec<&str> = list.iter().map(|g| g.name).collect();
    eprintln!(
        "wrote {} ({} genera, {per_row} a row: {}; each variants 0–{}{} side, top)",
        out.display(),
        list.len(),
        rows.join(", "),
        variants - 1,
        if seasons.len() > 1 { " × leaf-on, autumn, leaf-off," } else { "" }
    );
    Ok(())
}

pub(crate) fn library(command: &LibraryCommand) -> Result<()> {
    match command {
        LibraryCommand::List { json } => {
            let all = || GENERA.iter().chain(ARCHETYPES.iter());
            if *json {
                let rows: Vec<serde_json::Value> = all()
                    .map(|g| {
                        serde_json::json!({
                            "genus": g.name,
                            "archetype": g.archetype,
                            "family": g.family,
                            "conifer": g.conifer,
                            "deciduous": g.deciduous,
                            "leaf": format!("{:?}", g.leaf).to_lowercase(),
                            "bark": format!("{:?}", g.bark).to_lowercase(),
                            "crown_ratio": g.crown_ratio,
                            "height_m": g.params.scale,
                            "model": format!("library:{}", g.name),
                        })
                    })
                    .collect();
                print_all(&format!("{}\n", serde_json::Value::Array(rows)))?;
            } else {
                use std::fmt::Write as _;
                let mut text = String::new();
                writeln!(
                    text,
                    "{} genera and {} archetypes (use as --model NAME=library:GENUS[:VARIANT]; \
                     crown width/height at 40 cm DBH, typical height):",
                    GENERA.len(),
                    ARCHETYPES.len()
                )?;
                for g in all() {
                    if g.archetype && g.name == ARCHETYPES[0].name {
                        writeln!(text, "archetypes (for names the library cannot place):")?;
                    }
                    writeln!(
                        text,
                        "  {:<19} {:<14} {:<9} {:<10} leaves {:<8} bark {:<9} crown {:.2}  {:>4.0} m",
                        g.name,
                        g.family,
                        if g.conifer { "conifer" } else { "broadleaf" },
                        if g.deciduous { "deciduous" } else { "evergreen" },
                        format!("{:?}", g.leaf).to_lowercase(),
                        format!("{:?}", g.bark).to_lowercase(),
                        g.crown_ratio,
                        g.params.scale
                    )?;
                }
                print_all(&text)?;
            }
            Ok(())
        }
        LibraryCommand::Render { names, out, variants, size, per_row, seasons } => {
            let seasons: &[Season] = if *seasons { &Season::ALL } else { &[Season::LeafOn] };
            render_sheet(names, out, *variants, *size, *per_row, seasons)
        }
    }
}
