//! Tests of the placement readers.

use super::*;

#[test]
fn detects_lng_lat_columns_like_amsterdam() {
    let c = detect_columns(&["id", "species", "height", "dbh", "lat", "lng", "condition"]).unwrap();
    assert_eq!(c.kind, CoordKind::LonLat);
    assert_eq!((c.x, c.y), (5, 4));
    assert_eq!((c.id, c.species, c.height), (Some(0), Some(1), Some(2)));
}

#[test]
fn detects_projected_columns() {
    let c = detect_columns(&["X", "Y", "Z", "Species", "Height_m", "Yaw"]).unwrap();
    assert_eq!(c.kind, CoordKind::Projected);
    assert_eq!((c.z, c.species, c.height, c.yaw), (Some(2), Some(3), Some(4), Some(5)));
}

#[test]
fn header_without_coordinates_is_an_error_naming_the_header() {
    let e = detect_columns(&["name", "value"]).unwrap_err().to_string();
    assert!(e.contains("no coordinate columns") && e.contains("name"), "{e}");
}

#[test]
fn bad_rows_are_counted_not_fatal() {
    let csv = "id,lat,lng,height,species\n\
               1,52.37,4.90,15,Oak\n\
               2,NaN,4.90,15,Oak\n\
               3,,4.91,9,Pine\n\
               4,95.0,4.90,9,Pine\n\
               5,52.37,4.90,,Oak\n\
               6,52.38,abc,9,Oak\n\
               7,52.36,4.92,-3,Oak,extra\n";
    let set = read_csv(csv.as_bytes(), b',', &ReadOptions::default()).unwrap();
    assert_eq!(set.report.rows, 7);
    assert_eq!(set.rows.len(), 3, "{:?}", set.report);
    assert_eq!(set.report.skipped_total(), 4);
    assert_eq!(set.report.missing_height, 2); // row 5 empty, row 7 negative
    assert_eq!(set.rows[0].species.as_deref(), Some("Oak"));
    assert_eq!(set.rows[0].id, Some(1));
    assert_eq!(set.rows[0].height_m, Some(15.0));
    let lines = set.report.lines().join("\n");
    assert!(lines.contains("non-finite") && lines.contains("out of range"), "{lines}");
}

#[test]
fn geojson_points_and_properties() {
    let gj = br#"{"type":"FeatureCollection","features":[
        {"type":"Feature","geometry":{"type":"Point","coordinates":[15.4,48.4,210.5]},"properties":{"species":"pine","height":"21.5","id":42,"":"unnamed","girth":3}},
        {"type":"Feature","geometry":{"type":"MultiPoint","coordinates":[[15.41,48.41],[15.42,48.42]]},"properties":{"Species":"oak"}},
        {"type":"Feature","geometry":{"type":"LineString","coordinates":[[0,0],[1,1]]},"properties":{}},
        {"type":"Feature","geometry":null,"properties":{}}
    ]}"#;
    let set = read_geojson(gj, &ReadOptions::default()).unwrap();
    assert_eq!(set.rows.len(), 3);
    assert_eq!(set.rows[0].z, Some(210.5));
    assert_eq!(set.rows[0].height_m, Some(21.5));
    assert_eq!(set.rows[0].id, Some(42));
    assert_eq!(set.rows[2].species.as_deref(), Some("oak"));
    assert_eq!(set.report.skipped_total(), 2);
    // A property without a name is no attribute (it stopped the bake late).
    assert!(set.attribute_names.iter().all(|n| !n.is_empty()), "{:?}", set.attribute_names);
    assert!(set.attribute_names.iter().any(|n| n == "girth"), "{:?}", set.attribute_names);
    assert!(read_geojson(b"{\"type\":\"Topology\"}", &ReadOptions::default()).is_err());
    assert!(read_geojson(b"not json", &ReadOptions::default()).is_err());
}

#[test]
fn duplicates_are_counted() {
    let dir = std::env::temp_dir().join(format!("sylva-dup-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("d.csv");
    std::fs::write(&p, "x,y\n1,2\n1,2\n3,4\n").unwrap();
    let set = read_placements(&p).unwrap();
    assert_eq!(set.report.duplicate_coordinates, 1);
    assert_eq!(set.kind, CoordKind::Projected);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn latin1_rows_are_read_not_dropped() {
    // "Eiche müde" and a header "Höhe" in Windows-1252, as older spreadsheets export.
    let csv = b"lat,lon,species,h\xf6he\n52.1,4.9,Eiche m\xfcde,12\n52.2,4.8,Linde,9\n";
    let auto = read_csv(&csv[..], b',', &ReadOptions::default()).unwrap();
    assert_eq!(auto.rows.len(), 2, "{:?}", auto.report);
    assert_eq!(auto.rows[0].species.as_deref(), Some("Eiche müde"));
    assert_eq!(auto.report.not_utf8, 1);
    assert!(auto.report.lines().join("\n").contains("Windows-1252"));
    let strict = read_csv(&csv[..], b',', &ReadOptions { encoding: Encoding::Utf8, ..Default::default() }).unwrap();
    assert_eq!(strict.rows.len(), 1);
    assert!(strict.report.lines().join("\n").contains("--encoding latin1"), "{:?}", strict.report);
    let latin1 = read_csv(&csv[..], b',', &ReadOptions { encoding: Encoding::Latin1, ..Default::default() }).unwrap();
    assert_eq!(latin1.rows[0].species.as_deref(), Some("Eiche müde"));
    assert_eq!(latin1.report.not_utf8, 0, "asked for, so not reported");
}

#[test]
fn european_exports_with_semicolons_and_decimal_commas() {
    assert_eq!(detect_delimiter(b"lat;lon;soort;boomhoogte\r\n"), b';');
    assert_eq!(detect_delimiter(b"x\ty\tspecies\n"), b'\t');
    assert_eq!(detect_delimiter(b"\"a;b\",lat,lon\n"), b',', "separators inside quotes do not count");
    assert_eq!(detect_delimiter(b"lon\n"), b',');
    assert_eq!(parse_decimal_comma("52,3731"), Some(52.3731));
    assert_eq!(parse_decimal_comma("1.234,5"), Some(1234.5));
    assert_eq!(parse_decimal_comma("7.5"), Some(7.5));
    for bad in ["-4,5e", "1.2.3,4", "1,", "12.34,5"] {
        assert_eq!(parse_decimal_comma(bad), None, "{bad}");
    }
    assert_eq!(parse_f64("52,37"), None, "no decimal commas where the separator is a comma");
    let csv = "lat;lon;soort;boomhoogte\n52,3731;4,8922;Tilia;12,5\n52,3740;4,8930;Quercus;\n";
    let set = read_csv(csv.as_bytes(), b';', &ReadOptions::default()).unwrap();
    assert_eq!(set.rows.len(), 2, "{:?}", set.report);
    assert_eq!((set.rows[0].x, set.rows[0].y, set.rows[0].height_m), (4.8922, 52.3731, Some(12.5)));
    let swapped = read_csv(csv.as_bytes(), b';', &ReadOptions { swap_xy: true, ..Default::default() }).unwrap();
    assert_eq!((swapped.rows[0].x, swapped.rows[0].y), (52.3731, 4.8922));
}

#[test]
fn swapped_lon_lat_is_evident_in_the_report() {
    // Latitudes in the lon column and longitudes beyond ±90 in the lat column.
    let csv = "lon,lat\n-33.9,151.2\n-33.8,151.1\n";
    let set = read_csv(csv.as_bytes(), b',', &ReadOptions::default()).unwrap();
    assert_eq!((set.rows.len(), set.report.swappable), (0, 2));
    let fixed = read_csv(csv.as_bytes(), b',', &ReadOptions { swap_xy: true, ..Default::default() }).unwrap();
    assert_eq!((fixed.rows.len(), fixed.rows[0].x), (2, 151.2));
}

#[test]
fn geojson_points_without_coordinates_are_counted_and_projected_files_understood() {
    let gj = br#"{"type":"FeatureCollection","features":[
        {"type":"Feature","geometry":{"type":"Point"},"properties":{}},
        {"type":"Feature","geometry":{"type":"Point","coordinates":[]},"properties":{}},
        {"type":"Feature","geometry":{"type":"MultiPoint","coordinates":[]},"properties":{}},
        {"type":"Feature","geometry":{"type":"Point","coordinates":[4.9,52.37]},"properties":{}}
    ]}"#;
    let set = read_geojson(gj, &ReadOptions::default()).unwrap();
    assert_eq!((set.report.rows, set.rows.len(), set.report.skipped_total()), (4, 1, 3), "{:?}", set.report);
    // Dutch RD coordinates: refused as lon/lat with a hint, read with --input-crs or the crs member.
    let rd = br#"{"type":"FeatureCollection","features":[
        {"type":"Feature","geometry":{"type":"Point","coordinates":[121000.5,487000.25]},"properties":{"height":9}}]}"#;
    let e = read_geojson(rd, &ReadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("--input-crs") && e.contains("121000.5"), "{e}");
    let set = read_geojson(rd, &ReadOptions { projected: true, ..Default::default() }).unwrap();
    assert_eq!((set.kind, set.rows[0].x), (CoordKind::Projected, 121000.5));
    let named = br#"{"type":"FeatureCollection","crs":{"type":"name","properties":{"name":"urn:ogc:def:crs:EPSG::28992"}},
        "features":[{"type":"Feature","geometry":{"type":"Point","coordinates":[121000.5,487000.25]},"properties":{}}]}"#;
    assert_eq!(geojson_crs(&serde_json::from_slice(named).unwrap()), Some(28992));
    // ETRS89 (geographic) is lon/lat, not projected.
    let etrs = br#"{"type":"FeatureCollection","crs":{"type":"name","properties":{"name":"EPSG:4258"}},
        "features":[{"type":"Feature","geometry":{"type":"Point","coordinates":[4.9,52.37]},"properties":{}}]}"#;
    let set = read_geojson(etrs, &ReadOptions::default()).unwrap();
    assert_eq!((set.kind, set.declared_epsg, set.rows.len()), (CoordKind::LonLat, Some(4258), 1));
    // Sydney as [lat, lon]: the hint is --swap-xy, not a CRS.
    let sydney = br#"{"type":"FeatureCollection","features":[
        {"type":"Feature","geometry":{"type":"Point","coordinates":[-33.87,151.21]},"properties":{}}]}"#;
    let e = read_geojson(sydney, &ReadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("--swap-xy") && !e.contains("--input-crs"), "{e}");
    assert_eq!(read_geojson(named, &ReadOptions::default()).unwrap().kind, CoordKind::Projected);
}

#[test]
fn column_aliases_overrides_and_units() {
    // Every role's aliases are found, and the report names them.
    for (header, role, unit) in [
        (vec!["x", "y", "botanical_name", "dbh_mm"], ColumnRole::Species, Some(DbhUnit::Mm)),
        (vec!["x", "y", "scientific_name", "diameter_cm"], ColumnRole::Species, Some(DbhUnit::Cm)),
        (vec!["x", "y", "common_name", "DBH_in"], ColumnRole::Species, Some(DbhUnit::In)),
        (vec!["x", "y", "spp", "bhd"], ColumnRole::Species, Some(DbhUnit::Cm)),
        (vec!["x", "y", "species_code", "crown_radius"], ColumnRole::CrownRadius, None),
    ] {
        let c = detect_columns(&header).unwrap();
        assert!(c.species.is_some(), "{header:?}");
        assert!(c.used.iter().any(|(r, _)| *r == role), "{header:?}: {:?}", c.used);
        if let Some(u) = unit {
            assert_eq!((c.dbh.is_some(), c.dbh_unit), (true, u), "{header:?}");
        }
    }
    let c = detect_columns(&["x", "y", "species_code", "crown_radius"]).unwrap();
    assert_eq!(c.crown, Some((3, true)));
    // --column wins over the aliases; a name the header lacks is an error naming it.
    let options = ReadOptions {
        columns: vec![(ColumnRole::Species, "Soort".into()), (ColumnRole::Dbh, "stam".into())],
        dbh_unit: Some(DbhUnit::Mm),
        ..Default::default()
    };
    let c = detect_columns_with(&["lat", "lon", "species", "soort", "stam"], &options).unwrap();
    assert_eq!((c.species, c.dbh, c.dbh_unit), (Some(3), Some(4), DbhUnit::Mm));
    assert!(c.describe().contains("species ← \"soort\"") && c.describe().contains("dbh ← \"stam\" (mm)"));
    let bad = ReadOptions { columns: vec![(ColumnRole::Height, "hoogte".into())], ..Default::default() };
    let e = detect_columns_with(&["lat", "lon"], &bad).unwrap_err().to_string();
    assert!(e.contains("--column height=hoogte") && e.contains("lat"), "{e}");
    assert_eq!(ColumnRole::parse_mapping("crown=kroon").unwrap(), (ColumnRole::CrownDiameter, "kroon".into()));
    assert!(ColumnRole::parse_mapping("girth=omtrek").unwrap_err().contains("unknown role"));
    assert!(ColumnRole::parse_mapping("dbh").unwrap_err().contains("ROLE=COLUMN"));
}

#[test]
fn dbh_and_crowns_are_read_in_their_units_and_checked() {
    let csv = "lat,lon,dbh_mm,crown_radius\n52.0,4.0,350,3\n52.0,4.1,-5,0\n52.0,4.2,,200\n";
    let set = read_csv(csv.as_bytes(), b',', &ReadOptions::default()).unwrap();
    let dbh: Vec<Option<f32>> = set.rows.iter().map(|p| p.dbh_cm).collect();
    let crown: Vec<Option<f32>> = set.rows.iter().map(|p| p.crown_m).collect();
    assert_eq!(dbh, vec![Some(35.0), None, None], "mm → cm; negative dropped");
    assert_eq!(crown, vec![Some(6.0), None, None], "a radius doubled; 0 and 400 m dropped");
    // GeoJSON properties by the same names and units.
    let gj = br#"{"type":"FeatureCollection","features":[
        {"type":"Feature","geometry":{"type":"Point","coordinates":[4.0,52.0]},
         "properties":{"botanical_name":"Acer campestre","DBH_in":10,"crown_diameter":7.5}}]}"#;
    let set = read_geojson(gj, &ReadOptions::default()).unwrap();
    let p = &set.rows[0];
    assert_eq!((p.species.as_deref(), p.dbh_cm, p.crown_m), (Some("Acer campestre"), Some(25.4), Some(7.5)));
}

#[test]
fn named_columns_decide_over_detected_ones() {
    // Named x/y win over lon/lat columns that are also there.
    let options = ReadOptions {
        columns: vec![(ColumnRole::X, "rd_x".into()), (ColumnRole::Y, "rd_y".into())],
        ..Default::default()
    };
    let c = detect_columns_with(&["lon", "lat", "rd_x", "rd_y"], &options).unwrap();
    assert_eq!((c.kind, c.x, c.y), (CoordKind::Projected, 2, 3));
    // A named crown radius wins over a detected crown diameter.
    let options = ReadOptions { columns: vec![(ColumnRole::CrownRadius, "r".into())], ..Default::default() };
    let c = detect_columns_with(&["lat", "lon", "crown_diameter", "r"], &options).unwrap();
    assert_eq!(c.crown, Some((3, true)));
    // A role whose first alias is taken by a named column falls back to its next alias.
    let options = ReadOptions { columns: vec![(ColumnRole::Id, "species".into())], ..Default::default() };
    let c = detect_columns_with(&["lat", "lon", "species", "botanical_name"], &options).unwrap();
    assert_eq!((c.id, c.species), (Some(2), Some(3)));
    // Files that worked before pick the same species column: genus before taxon, type before art.
    assert_eq!(detect_columns(&["lat", "lon", "taxon", "genus"]).unwrap().species, Some(3));
    assert_eq!(detect_columns(&["lat", "lon", "art", "type"]).unwrap().species, Some(3));
    // A plain "diameter" is not taken as DBH (it often is the crown); dbh_m is metres.
    assert_eq!(detect_columns(&["lat", "lon", "diameter"]).unwrap().dbh, None);
    let c = detect_columns(&["lat", "lon", "dbh_m"]).unwrap();
    assert_eq!(c.dbh_unit, DbhUnit::M);
}

#[test]
fn a_header_cell_with_a_line_break_keeps_every_name_with_its_values() {
    // What a spreadsheet writes for Alt+Enter in a header cell: the
    // names after it must stay with their columns.
    let dir = std::env::temp_dir().join(format!("sylva-header-break-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("trees.csv");
    std::fs::write(
        &path,
        "id,x,y,\"crown\nwidth (m)\",condition,owner\n7,500000,5300000,4.5,good,city\n8,500010,5300000,3,poor,park\n",
    )
    .unwrap();
    let src = PlacementSource::open(&path, &ReadOptions::default()).unwrap();
    assert_eq!(src.attribute_names(), ["crown\nwidth (m)", "condition", "owner"]);
    let mut rows = Vec::new();
    src.for_each_with_attributes(&mut |p| {
        rows.push(p);
        Ok(())
    })
    .unwrap();
    assert_eq!(rows.len(), 2);
    let attrs: Vec<Vec<Option<String>>> = rows.iter().map(|p| p.attrs.clone()).collect();
    assert_eq!(attrs[0], [Some("4.5".into()), Some("good".into()), Some("city".into())]);
    assert_eq!(attrs[1][1].as_deref(), Some("poor"));
    // A header with no end within 1 MiB (an unclosed quote, or no CSV at all) is refused, saying so.
    let huge = dir.join("huge.csv");
    std::fs::write(&huge, format!("x,y,\"{}\n1,2,3\n", "a".repeat(MAX_HEADER_BYTES + 10))).unwrap();
    let e = PlacementSource::open(&huge, &ReadOptions::default()).err().unwrap();
    assert!(format!("{e:#}").contains("over 1024 KiB"), "{e:#}");
    // The record reader stops at the first line break outside quotes.
    assert_eq!(header_record(&b"a,\"b\nc\",d\r\n1,2,3\n"[..], 100).unwrap(), b"a,\"b\nc\",d\r\n");
    assert_eq!(header_record(&b"a,b"[..], 100).unwrap(), b"a,b");
    // A quote inside a field is a character, as the CSV reader reads it (an inch mark):
    // the header ends at its line break, not at the next quote in the data.
    assert_eq!(header_record(&b"id,x,y,dbh (\")\n1,2,3,\"4\"\n"[..], 100).unwrap(), b"id,x,y,dbh (\")\n");
    assert_eq!(header_record(&b"a;\"b \"\"c\"\"\nd\";e\n1;2;3\n"[..], 100).unwrap(), b"a;\"b \"\"c\"\"\nd\";e\n");
    assert_eq!(header_record(&b"\xef\xbb\xbf\"a\nb\",c\n1,2\n"[..], 100).unwrap(), b"\xef\xbb\xbf\"a\nb\",c\n");
    // Carriage returns end a record (old Mac files); blank lines before the header are skipped.
    assert_eq!(header_record(&b"x,y,id\r1,2,3\r"[..], 100).unwrap(), b"x,y,id\r");
    assert_eq!(header_record(&b"\r\n\nx,y\r\n1,2\r\n"[..], 100).unwrap(), b"\r\n\nx,y\r\n");
    // With the separator known (--delimiter ':'), a quote after another character is no quote.
    assert_eq!(header_record_with(&b"a:\"b\nc\":d\n1:2:3\n"[..], 100, Some(b':')).unwrap(), b"a:\"b\nc\":d\n");
    assert_eq!(header_record_with(&b"a;\"b\n1;2\n"[..], 100, Some(b',')).unwrap(), b"a;\"b\n");
    let inch = dir.join("inch.csv");
    std::fs::write(&inch, format!("x,y,height_ft\"\n{}", "1,2,3\n".repeat(200_000))).unwrap();
    let src = PlacementSource::open(&inch, &ReadOptions::default()).unwrap();
    // (Read, not refused for a header "over 1 MiB"; the name as the CSV reader gives it.)
    assert_eq!(src.attribute_names().len(), 1);
    assert!(src.attribute_names()[0].starts_with("height_ft"), "{:?}", src.attribute_names());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn ids_are_numbers_only_as_numbers_write_themselves_and_text_otherwise() {
    // An inventory's key is kept as given — a zero-padded "00123" is a key, not 123.
    assert_eq!((number_id("702"), text_id("702")), (Some(702), None));
    assert_eq!((number_id(" 702 "), text_id(" 702 ")), (Some(702), None));
    for key in ["00123", "+702", "702.0", "EY17080", "9223372036854775808", "18446744073709551616"] {
        assert_eq!((number_id(key), text_id(key).as_deref()), (None, Some(key)), "{key}");
    }
    assert_eq!((number_id(""), text_id("  ")), (None, None));
    assert_eq!(text_id(&"x".repeat(MAX_TEXT_ID_BYTES + 1)), None, "too long to keep");
    assert!(id_too_long(&"x".repeat(MAX_TEXT_ID_BYTES + 1)));
}
