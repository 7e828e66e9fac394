//! `sylva`: the native command line of the Sylva renderer.

#[cfg(not(target_arch = "wasm32"))]
mod cli {
    use std::path::PathBuf;

    use anyhow::{bail, Context, Result};
    use clap::{Parser, Subcommand, ValueEnum};
    use sylva::format::decode_pack;
    use sylva::render::capture::{render_pack_preview, PackView};
    use sylva::render::GpuContext;

    #[derive(Parser)]
    #[command(
        name = "sylva",
        version,
        about = "Sylva forest renderer: headless rendering of Sylva scenes and LoD packs."
    )]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Clone, Copy, ValueEnum)]
    enum View {
        Side,
        Oblique,
        Top,
    }

    #[derive(Subcommand)]
    enum Command {
        /// Render one species pack (one tree, lit) to a PNG.
        Render {
            /// LoD pack to render (`species/<name>.pack` of a scene).
            #[arg(long)]
            pack: PathBuf,
            /// Output PNG.
            #[arg(long)]
            out: PathBuf,
            /// Image size, WxH.
            #[arg(long, default_value = "512x512")]
            size: String,
            /// Where to look from.
            #[arg(long, value_enum, default_value_t = View::Oblique)]
            view: View,
            /// Mesh level to draw (0 = full detail).
            #[arg(long, default_value_t = 0)]
            level: usize,
        },
    }

    fn parse_size(s: &str) -> Result<(u32, u32)> {
        let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("--size {s:?}: expected WxH, e.g. 512x512"))?;
        let (w, h): (u32, u32) = (w.trim().parse()?, h.trim().parse()?);
        if w == 0 || h == 0 || w > 8192 || h > 8192 {
            bail!("--size {s}: each side must be 1–8192 pixels");
        }
        Ok((w, h))
    }

    pub fn main() -> Result<()> {
        match Cli::parse().command {
            Command::Render { pack, out, size, view, level } => {
                let (w, h) = parse_size(&size)?;
                let bytes = std::fs::read(&pack).with_context(|| format!("cannot read {}", pack.display()))?;
                let decoded = decode_pack(&pack.display().to_string(), &bytes)?;
                if level >= decoded.meta.mesh_levels.len() {
                    bail!("--level {level}: the pack has {} mesh levels", decoded.meta.mesh_levels.len());
                }
                let gpu = GpuContext::new_headless_blocking()?;
                let view = match view {
                    View::Side => PackView::Side,
                    View::Oblique => PackView::Oblique,
                    View::Top => PackView::Top,
                };
                let rgba = render_pack_preview(&gpu, &decoded, level, view, w, h, [0.62, 0.74, 0.86, 1.0]);
                image::save_buffer(&out, &rgba, w, h, image::ColorType::Rgba8)
                    .with_context(|| format!("cannot write {}", out.display()))?;
                eprintln!("wrote {} ({w}x{h}, {} on {})", out.display(), decoded.meta.name, gpu.adapter_summary());
                Ok(())
            }
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    if let Err(e) = cli::main() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

#[cfg(target_arch = "wasm32")]
fn main() {}
