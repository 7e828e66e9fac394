//! The GIS vector readers (issue 45) never panic, hang or allocate without
//! bound on hostile bytes: the first byte picks the format (Shapefile: the
//! next two bytes split the rest into its .shp and .dbf; FlatGeobuf; a
//! GeoPackage written to a file, as SQLite opens files), then every feature
//! is streamed, or an error comes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva_bake::input::gis::{for_each_fgb_feature, for_each_shp_feature, Layer, Wanted};

fuzz_target!(|data: &[u8]| {
    let Some((&kind, rest)) = data.split_first() else { return };
    let mut count = 0u64;
    let mut f = |_: sylva_bake::input::gis::Feature| {
        count += 1;
        Ok(())
    };
    match kind % 3 {
        0 if rest.len() >= 2 => {
            let split = usize::from(u16::from_le_bytes([rest[0], rest[1]])).min(rest.len() - 2);
            let (shp, dbf) = rest[2..].split_at(split);
            let _ = for_each_shp_feature(std::io::Cursor::new(shp), Some(std::io::Cursor::new(dbf)), None, &mut f);
        }
        1 => {
            let _ = for_each_fgb_feature(std::io::Cursor::new(rest), rest.len() as u64, &mut f);
        }
        _ => {
            let path = std::env::temp_dir().join(format!("sylva-fuzz-{}.gpkg", std::process::id()));
            if std::fs::write(&path, rest).is_ok() {
                if let Ok(layer) = Layer::open(&path, None, Wanted::Points) {
                    let _ = layer.for_each(&mut f);
                }
            }
        }
    }
});
