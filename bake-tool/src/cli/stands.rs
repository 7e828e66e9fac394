//! `sylva-bake stands`: the trees a stand map makes, as a CSV (to look at in
//! a GIS, to compare with an inventory), and the stand options `bake` shares.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use sylva_bake::input::allometry::Allometry;
use sylva_bake::input::placements::{PlacementSource, ReadOptions};
use sylva_bake::input::reproject::Crs;
use sylva_bake::input::stands::{Pattern, StandOptions, StandRole, MAX_STEMS_HA};

use super::log;

/// How stands become trees (`bake --stands`, `stands`).
#[derive(Args, Clone)]
pub(crate) struct StandArgs {
    /// Use stand field NAME for ROLE (repeatable). Roles: id, species, stems_ha,
    /// basal_area, height, top_height, dbh, weibull_shape, age, pattern.
    #[arg(long = "stand-column", value_name = "ROLE=NAME", value_parser = StandRole::parse_mapping)]
    pub(crate) stand_columns: Vec<(StandRole, String)>,
    /// Stems a hectare for stands that give neither stems/ha nor basal area.
    #[arg(long, value_name = "N", default_value_t = 400.0)]
    pub(crate) stand_density: f64,
    /// The pattern of stands that name none: regular (managed: evenly spaced),
    /// clustered (natural regeneration: groups of one species), random.
    #[arg(long, value_enum, default_value_t = Pattern::Regular)]
    pub(crate) stand_pattern: Pattern,
    /// The Weibull shape of stands' DBH distributions where a stand names none
    /// (3.6: the unimodal distribution of an even-aged stand; lower is wider).
    #[arg(long, value_name = "C", default_value_t = 3.6)]
    pub(crate) weibull_shape: f64,
}

impl StandArgs {
    /// Refuses values no stand has.
    pub(crate) fn check(&self) -> Result<()> {
        if !(self.stand_density > 0.0 && self.stand_density <= MAX_STEMS_HA) {
            bail!("--stand-density {}: stems a hectare, more than 0 and at most {MAX_STEMS_HA}", self.stand_density);
        }
        if !(0.5..20.0).contains(&self.weibull_shape) {
            bail!("--weibull-shape {}: a shape between 0.5 and 20", self.weibull_shape);
        }
        Ok(())
    }

    pub(crate) fn options(&self, allometry: &Allometry) -> StandOptions {
        StandOptions {
            columns: self.stand_columns.clone(),
            default_stems_ha: self.stand_density,
            pattern: self.stand_pattern,
            weibull_shape: self.weibull_shape,
            allometry: Some(Arc::new(allometry.clone())),
        }
    }
}

/// `sylva-bake stands`.
#[derive(Args)]
pub(crate) struct StandsArgs {
    /// The stand map: polygons (GeoJSON, Shapefile, GeoPackage, FlatGeobuf).
    pub(crate) stands: PathBuf,
    /// The trees as CSV (x, y in the stand map's CRS, species, dbh_cm, height_m,
    /// crown_m from the allometry, stand); `-` for standard output.
    #[arg(long, value_name = "FILE.csv")]
    pub(crate) out: PathBuf,
    /// The GeoPackage table to read.
    #[arg(long, value_name = "NAME")]
    pub(crate) layer: Option<String>,
    /// The stand map's CRS where it names none (or names a wrong one).
    #[arg(long)]
    pub(crate) input_crs: Option<String>,
    #[command(flatten)]
    pub(crate) stand: StandArgs,
}

pub(crate) fn stands(args: &StandsArgs) -> Result<()> {
    args.stand.check()?;
    let allometry = Allometry::built_in();
    let input_crs = args.input_crs.as_deref().map(Crs::parse).transpose()?;
    let read = ReadOptions {
        projected: input_crs.as_ref().is_some_and(|c| !c.is_geographic()),
        geographic_input: input_crs.as_ref().is_some_and(Crs::is_geographic),
        layer: args.layer.clone(),
        stands: Some(Arc::new(args.stand.options(&allometry))),
        ..Default::default()
    };
    let source = PlacementSource::open(&args.stands, &read)?;
    for n in &source.notes {
        log(&format!("stands: {n}"));
    }
    let out: Box<dyn Write> = if args.out.as_os_str() == "-" {
        Box::new(std::io::stdout().lock())
    } else {
        if args.out.exists() {
            bail!("--out {}: exists (nothing is overwritten)", args.out.display());
        }
        Box::new(std::fs::File::create(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?)
    };
    let mut w = std::io::BufWriter::new(out);
    writeln!(w, "x,y,species,dbh_cm,height_m,crown_m,stand")?;
    let report = source.for_each_with_attributes(&mut |p| {
        let species = p.species.unwrap_or_default();
        let crown = p.dbh_cm.map(|d| allometry.for_label(&species).crown.metres(f64::from(d)));
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.2}"));
        let quote =
            |s: &str| if s.contains([',', '"']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() };
        writeln!(
            w,
            "{},{},{},{},{},{},{}",
            p.x,
            p.y,
            quote(&species),
            opt(p.dbh_cm.map(f64::from)),
            opt(p.height_m.map(f64::from)),
            opt(crown),
            quote(p.attrs.first().cloned().flatten().as_deref().unwrap_or(""))
        )?;
        Ok(())
    })?;
    w.flush()?;
    log(&format!("stands: {} trees written to {}", report.kept, args.out.display()));
    Ok(())
}
