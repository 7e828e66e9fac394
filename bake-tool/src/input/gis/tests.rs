//! GIS layers written by the tests (shapefile, flatgeobuf and rusqlite
//! writers), read back as placements.

use std::path::{Path, PathBuf};

use crate::input::placements::{CoordKind, Placement, PlacementSource, ReadOptions};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sylva-gis-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// ISO WKB of a point (little-endian).
pub(crate) fn wkb_point(x: f64, y: f64) -> Vec<u8> {
    let mut b = vec![1u8];
    b.extend(1u32.to_le_bytes());
    b.extend(x.to_le_bytes());
    b.extend(y.to_le_bytes());
    b
}

/// ISO WKB of a polygon of one ring.
pub(crate) fn wkb_polygon(ring: &[[f64; 2]]) -> Vec<u8> {
    let mut b = vec![1u8];
    b.extend(3u32.to_le_bytes());
    b.extend(1u32.to_le_bytes());
    b.extend((ring.len() as u32).to_le_bytes());
    for p in ring {
        b.extend(p[0].to_le_bytes());
        b.extend(p[1].to_le_bytes());
    }
    b
}

/// GeoPackage binary: the `GP` header (no envelope), then WKB.
pub(crate) fn gpkg_blob(srs_id: i32, wkb: &[u8]) -> Vec<u8> {
    let mut b = b"GP".to_vec();
    b.push(0); // version
    b.push(0b0000_0001); // little-endian, no envelope
    b.extend(srs_id.to_le_bytes());
    b.extend(wkb);
    b
}

const RD_NEW_ESRI: &str = r#"PROJCS["RD_New",GEOGCS["GCS_Amersfoort",DATUM["D_Amersfoort",SPHEROID["Bessel_1841",6377397.155,299.1528128]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Double_Stereographic"],PARAMETER["False_Easting",155000.0],PARAMETER["False_Northing",463000.0],PARAMETER["Central_Meridian",5.38763888888889],PARAMETER["Scale_Factor",0.9999079],PARAMETER["Latitude_Of_Origin",52.15616055555555],UNIT["Meter",1.0]]"#;

/// A point Shapefile of three street trees in RD New (EPSG:28992), its
/// fields as a city exports them (names cut to 10 bytes by dBase).
pub(crate) fn write_tree_shapefile(path: &Path, prj: Option<&str>) {
    use dbase::{FieldName, FieldValue, Record, TableWriterBuilder};
    let table = TableWriterBuilder::new()
        .add_character_field(FieldName::try_from("species_co").unwrap(), 60)
        .add_numeric_field(FieldName::try_from("dbh_mm").unwrap(), 10, 0)
        .add_numeric_field(FieldName::try_from("hoogte").unwrap(), 10, 1)
        .add_numeric_field(FieldName::try_from("tree_id").unwrap(), 10, 0)
        .add_character_field(FieldName::try_from("buurt").unwrap(), 40);
    let mut w = shapefile::Writer::from_path(path, table).unwrap();
    let rows = [
        (121_000.0, 487_000.0, "Tilia × europaea 'Pallida'", 420.0, 17.5, 1.0, "Jordaan"),
        (121_010.0, 487_005.0, "Platanus x hispanica", 610.0, 24.0, 2.0, "Jordaan"),
        (121_020.0, 487_010.0, "Gewone es", 300.0, 14.0, 3.0, "De Pijp"),
    ];
    for (x, y, species, dbh, h, id, buurt) in rows {
        let mut r = Record::default();
        r.insert("species_co".into(), FieldValue::Character(Some(species.into())));
        r.insert("dbh_mm".into(), FieldValue::Numeric(Some(dbh)));
        r.insert("hoogte".into(), FieldValue::Numeric(Some(h)));
        r.insert("tree_id".into(), FieldValue::Numeric(Some(id)));
        r.insert("buurt".into(), FieldValue::Character(Some(buurt.into())));
        w.write_shape_and_record(&shapefile::Point::new(x, y), &r).unwrap();
    }
    drop(w);
    if let Some(prj) = prj {
        std::fs::write(path.with_extension("prj"), prj).unwrap();
    }
    std::fs::write(path.with_extension("cpg"), "UTF-8").unwrap();
}

fn read_all(path: &Path, options: &ReadOptions) -> (PlacementSource, Vec<Placement>, crate::input::placements::Report) {
    let source = PlacementSource::open(path, options).unwrap();
    let mut rows = Vec::new();
    let report = source
        .for_each_with_attributes(&mut |p| {
            rows.push(p);
            Ok(())
        })
        .unwrap();
    (source, rows, report)
}

#[test]
fn a_shapefile_of_trees_reads_as_placements() {
    let d = dir("shp");
    let shp = d.join("bomen.shp");
    write_tree_shapefile(&shp, Some(RD_NEW_ESRI));
    let (source, rows, report) = read_all(&shp, &ReadOptions::default());
    assert_eq!(source.kind, CoordKind::Projected);
    assert_eq!(source.declared_epsg, Some(28992), "the ESRI .prj's name is RD New");
    let notes = source.notes.join("; ");
    assert!(notes.contains("species ← \"species_co\""), "{notes}");
    assert!(notes.contains("dbh ← \"dbh_mm (mm)\""), "{notes}");
    assert_eq!((report.rows, report.kept), (3, 3));
    assert_eq!(rows[0].species.as_deref(), Some("Tilia × europaea 'Pallida'"));
    assert_eq!(rows[1].dbh_cm, Some(61.0));
    assert_eq!(rows[2].height_m, Some(14.0), "hoogte is Dutch for height");
    assert_eq!(rows.iter().map(|r| r.id).collect::<Vec<_>>(), [Some(1), Some(2), Some(3)]);
    assert_eq!((rows[0].x, rows[0].y), (121_000.0, 487_000.0));
    assert!(rows[0].z.is_none(), "a 2D point has no ground height");
    let names = source.attribute_names();
    let buurt = names.iter().position(|n| n == "buurt").expect("an attribute");
    assert_eq!(rows[2].attrs[buurt].as_deref(), Some("De Pijp"));
    // --column with the whole name finds the cut field.
    let options = ReadOptions {
        columns: vec![(crate::input::placements::ColumnRole::Species, "species_code".into())],
        ..Default::default()
    };
    let (_, rows, _) = read_all(&shp, &options);
    assert_eq!(rows[1].species.as_deref(), Some("Platanus x hispanica"));
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn a_shapefile_without_its_prj_says_what_to_do() {
    let d = dir("noprj");
    let shp = d.join("bomen.shp");
    write_tree_shapefile(&shp, None);
    let e = format!("{:#}", PlacementSource::open(&shp, &ReadOptions::default()).err().unwrap());
    assert!(e.contains("no .prj") && e.contains("--input-crs"), "{e}");
    // With --input-crs it reads.
    let (source, rows, _) = read_all(&shp, &ReadOptions { projected: true, ..Default::default() });
    assert_eq!((source.kind, rows.len()), (CoordKind::Projected, 3));
    // Without its .dbf: geometries only, said so.
    std::fs::remove_file(shp.with_extension("dbf")).unwrap();
    let (source, rows, _) = read_all(&shp, &ReadOptions { projected: true, ..Default::default() });
    assert!(source.notes.join(" ").contains("no .dbf"), "{:?}", source.notes);
    assert_eq!(rows.len(), 3);
    assert!(rows[0].species.is_none());
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn hostile_and_wrong_gis_files_get_errors() {
    let d = dir("hostile");
    let shp = d.join("bomen.shp");
    write_tree_shapefile(&shp, Some(RD_NEW_ESRI));
    let bytes = std::fs::read(&shp).unwrap();
    // Cut in the middle of a record: the records before it are read, then an error.
    std::fs::write(&shp, &bytes[..bytes.len() - 7]).unwrap();
    // (Opening looks at the first hundred features, so it finds the cut already.)
    let e = match PlacementSource::open(&shp, &ReadOptions::default()) {
        Ok(source) => format!("{:#}", source.for_each(&mut |_| Ok(())).expect_err("a cut record")),
        Err(e) => format!("{e:#}"),
    };
    assert!(e.contains("feature 3") && e.contains("bomen.shp"), "{e}");
    // Garbage of every kind: errors, no panic.
    for (name, junk) in [
        ("junk.shp", b"not a shapefile at all".to_vec()),
        ("junk.fgb", b"fgb\x03fgb\x00\xff\xff\xff\xff".to_vec()),
        ("junk.gpkg", b"SQLite format 3\x00 but then nothing".to_vec()),
        ("empty.gpkg", Vec::new()),
    ] {
        let p = d.join(name);
        std::fs::write(&p, junk).unwrap();
        let e = format!("{:#}", PlacementSource::open(&p, &ReadOptions::default()).err().expect(name));
        assert!(e.contains(name), "{name}: {e}");
    }
    // A .prj that is no CRS.
    std::fs::write(&shp, &bytes).unwrap();
    std::fs::write(shp.with_extension("prj"), "PROJCS[\"made up\",NONSENSE[1]]").unwrap();
    let e = format!("{:#}", PlacementSource::open(&shp, &ReadOptions::default()).err().unwrap());
    assert!(e.contains("bomen.prj") && e.contains("made up"), "{e}");
    std::fs::remove_dir_all(d).ok();
}

/// A GeoPackage with a table of trees (EPSG:4326) and one of stands.
pub(crate) fn write_geopackage(path: &Path) {
    let c = rusqlite::Connection::open(path).unwrap();
    c.execute_batch(
        "CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT, srs_id INTEGER PRIMARY KEY, organization TEXT, \
           organization_coordsys_id INTEGER, definition TEXT, description TEXT);
         INSERT INTO gpkg_spatial_ref_sys VALUES ('WGS 84', 4326, 'EPSG', 4326, 'GEOGCS[\"WGS 84\"]', NULL);
         INSERT INTO gpkg_spatial_ref_sys VALUES ('ETRS89 / UTM 32N', 25832, 'EPSG', 25832, 'x', NULL);
         CREATE TABLE gpkg_contents (table_name TEXT PRIMARY KEY, data_type TEXT, identifier TEXT, \
           description TEXT, last_change TEXT, min_x REAL, min_y REAL, max_x REAL, max_y REAL, srs_id INTEGER);
         CREATE TABLE gpkg_geometry_columns (table_name TEXT, column_name TEXT, geometry_type_name TEXT, \
           srs_id INTEGER, z INTEGER, m INTEGER);
         CREATE TABLE baeume (fid INTEGER PRIMARY KEY, geom BLOB, Baumart TEXT, Hoehe_m REAL, BHD_cm REAL);
         CREATE TABLE bestaende (fid INTEGER PRIMARY KEY, shape BLOB, name TEXT);
         INSERT INTO gpkg_contents (table_name, data_type, srs_id) VALUES ('baeume', 'features', 4326);
         INSERT INTO gpkg_contents (table_name, data_type, srs_id) VALUES ('bestaende', 'features', 25832);
         INSERT INTO gpkg_geometry_columns VALUES ('baeume', 'geom', 'POINT', 4326, 0, 0);
         INSERT INTO gpkg_geometry_columns VALUES ('bestaende', 'shape', 'POLYGON', 25832, 0, 0);",
    )
    .unwrap();
    let trees = [(11.57, 48.14, "Rotbuche", 28.5, 41.0), (11.5702, 48.1401, "Stieleiche", 24.0, 55.5)];
    for (x, y, art, h, bhd) in trees {
        c.execute(
            "INSERT INTO baeume (geom, Baumart, Hoehe_m, BHD_cm) VALUES (?1, ?2, ?3, ?4)",
            rusqlite::params![gpkg_blob(4326, &wkb_point(x, y)), art, h, bhd],
        )
        .unwrap();
    }
    // A row with no geometry, one with a broken one.
    c.execute("INSERT INTO baeume (geom, Baumart) VALUES (NULL, 'Fichte')", []).unwrap();
    let ring = [[500_000.0, 5_300_000.0], [500_100.0, 5_300_000.0], [500_100.0, 5_300_100.0], [500_000.0, 5_300_000.0]];
    c.execute(
        "INSERT INTO bestaende (shape, name) VALUES (?1, 'Abt. 12a')",
        rusqlite::params![gpkg_blob(25832, &wkb_polygon(&ring))],
    )
    .unwrap();
}

#[test]
fn a_geopackage_layer_of_trees_reads_as_placements() {
    let d = dir("gpkg");
    let gpkg = d.join("inventur.gpkg");
    write_geopackage(&gpkg);
    let (source, rows, report) = read_all(&gpkg, &ReadOptions::default());
    assert_eq!(source.kind, CoordKind::LonLat, "EPSG:4326 is lon/lat");
    assert_eq!(source.declared_epsg, Some(4326));
    assert!(source.notes.join(" ").contains("table baeume"), "the table of points: {:?}", source.notes);
    assert_eq!((report.rows, report.kept), (3, 2));
    assert_eq!(report.skipped.get("no geometry").map(|s| s.0), Some(1));
    assert_eq!(rows[0].species.as_deref(), Some("Rotbuche"));
    assert_eq!(rows[1].height_m, Some(24.0), "Hoehe_m");
    assert_eq!(rows[1].dbh_cm, Some(55.5), "BHD_cm");
    assert_eq!((rows[0].x, rows[0].y), (11.57, 48.14));
    // --layer picks the other table; as placements it holds no points.
    let e = format!(
        "{:#}",
        PlacementSource::open(&gpkg, &ReadOptions { layer: Some("bestaende".into()), ..Default::default() })
            .err()
            .unwrap()
    );
    assert!(e.contains("polygons, not points"), "{e}");
    let e = format!(
        "{:#}",
        PlacementSource::open(&gpkg, &ReadOptions { layer: Some("nope".into()), ..Default::default() }).err().unwrap()
    );
    assert!(e.contains("baeume (point)") && e.contains("bestaende (polygon)"), "{e}");
    std::fs::remove_dir_all(d).ok();
}

/// A FlatGeobuf of points in EPSG:32633 with the given properties.
pub(crate) fn write_flatgeobuf(path: &Path, points: &[(f64, f64, &str, f64)]) {
    use flatgeobuf::{ColumnType, FgbCrs, FgbWriter, FgbWriterOptions, GeometryType};
    use geozero::{ColumnValue, PropertyProcessor};
    let options = FgbWriterOptions { crs: FgbCrs { code: 32633, ..Default::default() }, ..Default::default() };
    let mut fgb = FgbWriter::create_with_options("stand", GeometryType::Point, options).unwrap();
    fgb.add_column("species", ColumnType::String, |_, _| {});
    fgb.add_column("height", ColumnType::Double, |_, _| {});
    for (x, y, species, h) in points {
        fgb.add_feature_geom(geozero::wkb::Wkb(wkb_point(*x, *y)), |f| {
            f.property(0, "species", &ColumnValue::String(species)).unwrap();
            f.property(1, "height", &ColumnValue::Double(*h)).unwrap();
        })
        .unwrap();
    }
    let mut out = std::fs::File::create(path).unwrap();
    fgb.write(&mut out).unwrap();
}

#[test]
fn a_flatgeobuf_of_trees_reads_as_placements() {
    let d = dir("fgb");
    let fgb = d.join("stand.fgb");
    write_flatgeobuf(
        &fgb,
        &[(500_000.0, 5_300_000.0, "Picea abies", 31.0), (500_010.0, 5_300_004.0, "Fagus sylvatica", 27.5)],
    );
    let (source, rows, report) = read_all(&fgb, &ReadOptions::default());
    assert_eq!((source.kind, source.declared_epsg), (CoordKind::Projected, Some(32633)));
    assert_eq!(report.kept, 2);
    // The writer's spatial index orders the features: find them by name.
    let fagus = rows.iter().find(|r| r.species.as_deref() == Some("Fagus sylvatica")).expect("Fagus");
    let picea = rows.iter().find(|r| r.species.as_deref() == Some("Picea abies")).expect("Picea");
    assert_eq!((picea.height_m, fagus.height_m), (Some(31.0), Some(27.5)));
    assert_eq!((fagus.x, fagus.y), (500_010.0, 5_300_004.0));
    std::fs::remove_dir_all(d).ok();
}

/// Valid files with bytes flipped, cut or repeated (deterministic): every
/// reader returns features or an error, never panics (`make fuzz`'s
/// `read_gis` target searches further).
#[test]
fn mutated_gis_files_never_panic() {
    let d = dir("mutated");
    let shp = d.join("bomen.shp");
    write_tree_shapefile(&shp, Some(RD_NEW_ESRI));
    let fgb = d.join("stand.fgb");
    write_flatgeobuf(&fgb, &[(500_000.0, 5_300_000.0, "Picea abies", 31.0), (500_010.0, 5_300_004.0, "Fagus", 27.5)]);
    let gpkg = d.join("inventur.gpkg");
    write_geopackage(&gpkg);
    let (shp_bytes, dbf_bytes) = (std::fs::read(&shp).unwrap(), std::fs::read(shp.with_extension("dbf")).unwrap());
    let (fgb_bytes, gpkg_bytes) = (std::fs::read(&fgb).unwrap(), std::fs::read(&gpkg).unwrap());
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut mutate = |bytes: &[u8]| -> Vec<u8> {
        let mut b = bytes.to_vec();
        match next() % 4 {
            0 => b.truncate((next() as usize) % b.len().max(1)),
            1 => {
                let at = (next() as usize) % b.len().max(1);
                b.splice(at..at, bytes[..(next() as usize % 64).min(bytes.len())].iter().copied());
            }
            _ => {
                for _ in 0..1 + next() % 8 {
                    let at = (next() as usize) % b.len().max(1);
                    if let Some(x) = b.get_mut(at) {
                        *x = if next() % 2 == 0 { 0xFF } else { next() as u8 };
                    }
                }
            }
        }
        b
    };
    let mut ok = [0u32; 3];
    for _ in 0..120 {
        let (s, dbf) = (mutate(&shp_bytes), mutate(&dbf_bytes));
        let r = super::for_each_shp_feature(
            std::io::Cursor::new(s),
            Some(std::io::Cursor::new(dbf)),
            None,
            &mut |_| Ok(()),
        );
        ok[0] += u32::from(r.is_ok());
        let m = mutate(&fgb_bytes);
        let r = super::for_each_fgb_feature(std::io::Cursor::new(&m), m.len() as u64, &mut |_| Ok(()));
        ok[1] += u32::from(r.is_ok());
    }
    let path = d.join("mutated.gpkg");
    for _ in 0..40 {
        std::fs::write(&path, mutate(&gpkg_bytes)).unwrap();
        if let Ok(layer) = super::Layer::open(&path, None, super::Wanted::Points) {
            ok[2] += u32::from(layer.for_each(&mut |_| Ok(())).is_ok());
        }
    }
    // Some mutations leave a readable file, most do not: both paths ran.
    assert!(ok.iter().all(|&n| n > 0), "{ok:?}");
    std::fs::remove_dir_all(d).ok();
}

/// What the second read found: a FlatGeobuf of one feature (its index has a
/// leaf and a root), a `.dbf` row marked deleted, a PointZ of Z = 0, text in
/// Windows-1252 without a `.cpg`, a polygon record whose counts exceed it.
#[test]
fn one_feature_files_deleted_rows_zero_z_and_latin1_text() {
    let d = dir("second-read");
    let fgb = d.join("one.fgb");
    write_flatgeobuf(&fgb, &[(500_000.0, 5_300_000.0, "Picea abies", 31.0)]);
    let (_, rows, _) = read_all(&fgb, &ReadOptions::default());
    assert_eq!(rows.len(), 1, "one indexed feature");

    let shp = d.join("bomen.shp");
    write_tree_shapefile(&shp, Some(RD_NEW_ESRI));
    let dbf = shp.with_extension("dbf");
    let mut bytes = std::fs::read(&dbf).unwrap();
    let header = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    let record = usize::from(u16::from_le_bytes([bytes[10], bytes[11]]));
    bytes[header + record] = b'*'; // the second row deleted
    std::fs::write(&dbf, &bytes).unwrap();
    let (_, rows, report) = read_all(&shp, &ReadOptions::default());
    let species: Vec<_> = rows.iter().map(|r| r.species.clone().unwrap_or_default()).collect();
    assert_eq!(species, ["Tilia × europaea 'Pallida'", "Gewone es"], "rows stay with their shapes");
    assert_eq!(rows[1].id, Some(3));
    assert_eq!(report.skipped.get("not a point: a record deleted in the .dbf").map(|s| s.0), Some(1));

    // Windows-1252 bytes, no .cpg, no code page mark: read as Windows-1252.
    bytes[header + record] = b' ';
    let at = bytes.windows(5).position(|w| w == b"Gewon").unwrap();
    bytes[at + 1] = 0xE9; // é
    bytes[29] = 0;
    std::fs::write(&dbf, &bytes).unwrap();
    std::fs::remove_file(shp.with_extension("cpg")).unwrap();
    let (_, rows, _) = read_all(&shp, &ReadOptions::default());
    assert_eq!(rows[2].species.as_deref(), Some("Géwone es"));

    // PointZ with Z = 0 (no ground height) and Z = 12.5 (one).
    let zshp = d.join("z.shp");
    let mut w = shapefile::ShapeWriter::from_path(&zshp).unwrap();
    w.write_shape(&shapefile::PointZ::new(121_000.0, 487_000.0, 0.0, 0.0)).unwrap();
    w.write_shape(&shapefile::PointZ::new(121_010.0, 487_000.0, 12.5, 0.0)).unwrap();
    drop(w);
    std::fs::write(zshp.with_extension("prj"), RD_NEW_ESRI).unwrap();
    let (_, rows, _) = read_all(&zshp, &ReadOptions::default());
    assert_eq!(rows.iter().map(|r| r.z).collect::<Vec<_>>(), [None, Some(12.5)]);

    // A polygon record whose point count would need gigabytes.
    let pshp = d.join("poly.shp");
    let ring = vec![
        shapefile::Point::new(0.0, 0.0),
        shapefile::Point::new(0.0, 10.0),
        shapefile::Point::new(10.0, 10.0),
        shapefile::Point::new(0.0, 0.0),
    ];
    let mut w = shapefile::ShapeWriter::from_path(&pshp).unwrap();
    w.write_shape(&shapefile::Polygon::new(shapefile::PolygonRing::Outer(ring))).unwrap();
    drop(w);
    let mut b = std::fs::read(&pshp).unwrap();
    b[148..152].copy_from_slice(&0x1000_0000u32.to_le_bytes()); // num_points
    std::fs::write(&pshp, &b).unwrap();
    let mut none = |_| Ok(());
    let e = super::for_each_shp_feature(std::io::Cursor::new(b), None::<std::io::Cursor<Vec<u8>>>, None, &mut none)
        .unwrap_err()
        .to_string();
    assert!(e.contains("feature 1") && e.contains("counts need"), "{e}");
    std::fs::remove_dir_all(d).ok();
}
