//! Stands become trees: counts, shares, spacing, DBH, heights, holes,
//! determinism, and stands that make none.

use super::*;

fn square(x0: f64, y0: f64, side: f64) -> Vec<[f64; 2]> {
    vec![[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side], [x0, y0]]
}

fn stand(pattern: Pattern, stems_ha: f64, mix: &str) -> Stand {
    Stand {
        id: "12a".into(),
        mix: parse_mix(mix),
        stems_ha,
        height: Some((24.0, false)),
        dbh_cm: Some(30.0),
        shape: 3.6,
        pattern,
        assumed: Vec::new(),
        area_m2: 0.0,
    }
}

fn grow(s: &mut Stand, polygons: &[Vec<Vec<[f64; 2]>>]) -> Vec<Stem> {
    s.area_m2 = area(polygons);
    grow_stand(s, polygons, None, &StandOptions::default())
}

/// Mean nearest-neighbour distance of points.
fn mean_nn(points: &[[f64; 2]]) -> f64 {
    let d: f64 = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            points
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
                .fold(f64::MAX, f64::min)
        })
        .sum();
    d / points.len() as f64
}

#[test]
fn species_mixes_read_as_foresters_write_them() {
    let m = parse_mix("Picea abies:60;Fagus sylvatica:40");
    assert_eq!(m, vec![("Picea abies".into(), 0.6), ("Fagus sylvatica".into(), 0.4)]);
    let m = parse_mix("Pinus sylvestris 70%, Betula pendula 30%");
    assert_eq!(m[1], ("Betula pendula".into(), 0.3));
    assert_eq!(parse_mix("Quercus robur"), vec![("Quercus robur".into(), 1.0)]);
    // Shares as fractions; a name without a share takes what is left.
    let m = parse_mix("Fichte=0.5; Tanne; Buche");
    assert_eq!(m.iter().map(|e| (e.1 * 100.0).round()).collect::<Vec<_>>(), [50.0, 25.0, 25.0]);
    assert!(parse_mix(" ; ").is_empty());
    assert!((gamma(1.0 + 1.0 / 3.6) - 0.9011).abs() < 1e-3, "{}", gamma(1.0 + 1.0 / 3.6));
    assert!((gamma(5.0) - 24.0).abs() < 1e-9);
}

#[test]
fn a_stand_makes_its_stems_its_shares_and_its_sizes() {
    // 4 ha at 500 stems/ha: 2,000 stems, 60/40.
    let polygons = vec![vec![square(0.0, 0.0, 200.0)]];
    let mut s = stand(Pattern::Regular, 500.0, "Picea abies:60;Fagus sylvatica:40");
    let stems = grow(&mut s, &polygons);
    assert!((1999..=2001).contains(&stems.len()), "{}", stems.len());
    let picea = stems.iter().filter(|t| t.species == 0).count() as f64 / stems.len() as f64;
    assert!((picea - 0.6).abs() < 0.001, "exact shares: {picea}");
    assert!(stems.iter().all(|t| (0.0..=200.0).contains(&t.xy[0]) && (0.0..=200.0).contains(&t.xy[1])));
    // DBH: the stand's quadratic mean within 5 % (its basal area: stems × π dg²/4); heights: its mean.
    let mean = |v: Vec<f32>| v.iter().map(|x| f64::from(*x)).sum::<f64>() / v.len() as f64;
    let dg = mean(stems.iter().map(|t| t.dbh_cm.unwrap().powi(2)).collect()).sqrt();
    assert!((dg - 30.0).abs() < 1.5, "{dg}");
    let h = mean(stems.iter().map(|t| t.height_m.unwrap()).collect());
    assert!((h - 24.0).abs() < 0.01, "{h}");
    // The same on every call.
    assert_eq!(grow(&mut s.clone(), &polygons), stems);
}

#[test]
fn patterns_look_like_forests_not_white_noise() {
    // Clark & Evans (1954): R = mean nearest-neighbour distance ÷ 0.5/√λ;
    // 1 for a Poisson pattern, > 1 regular, < 1 clustered.
    let polygons = vec![vec![square(0.0, 0.0, 100.0)]];
    let r = |pattern| {
        let mut s = stand(pattern, 600.0, "Picea abies");
        let stems = grow(&mut s, &polygons);
        let pts: Vec<[f64; 2]> = stems.iter().map(|t| t.xy).collect();
        let lambda = pts.len() as f64 / 10_000.0;
        mean_nn(&pts) / (0.5 / lambda.sqrt())
    };
    let (regular, random, clustered) = (r(Pattern::Regular), r(Pattern::Random), r(Pattern::Clustered));
    assert!(regular > 1.3, "regular R = {regular}");
    assert!((0.8..1.2).contains(&random), "random R = {random}");
    assert!(clustered < 0.9, "clustered R = {clustered}");
    // The hard core: no two regular stems closer than half the mean spacing.
    let mut s = stand(Pattern::Regular, 600.0, "Picea abies");
    let stems = grow(&mut s, &polygons);
    let spacing = (10_000.0 / stems.len() as f64).sqrt();
    for (i, a) in stems.iter().enumerate() {
        for b in &stems[i + 1..] {
            let d = ((a.xy[0] - b.xy[0]).powi(2) + (a.xy[1] - b.xy[1]).powi(2)).sqrt();
            assert!(d > 0.5 * spacing, "{d} m apart at {spacing} m spacing");
        }
    }
}

#[test]
fn holes_stay_empty_and_clustered_mixtures_come_in_groups() {
    // A 100 m square with a 50 m hole (a meadow): 0.75 ha.
    let polygons = vec![vec![square(0.0, 0.0, 100.0), square(25.0, 25.0, 50.0)]];
    assert!((area(&polygons) - 7_500.0).abs() < 1e-6);
    let mut s = stand(Pattern::Clustered, 800.0, "Picea abies:50;Fagus sylvatica:50");
    let stems = grow(&mut s, &polygons);
    assert!((599..=601).contains(&stems.len()), "{}", stems.len());
    assert!(stems.iter().all(|t| !(t.xy[0] > 25.0 && t.xy[0] < 75.0 && t.xy[1] > 25.0 && t.xy[1] < 75.0)));
    // In groups: a stem's nearest neighbour is mostly of its own species.
    let same = stems
        .iter()
        .enumerate()
        .filter(|(i, a)| {
            let nearest = stems
                .iter()
                .enumerate()
                .filter(|(j, _)| j != i)
                .min_by(|(_, p), (_, q)| {
                    let d = |t: &Stem| (t.xy[0] - a.xy[0]).powi(2) + (t.xy[1] - a.xy[1]).powi(2);
                    d(p).total_cmp(&d(q))
                })
                .unwrap()
                .1;
            nearest.species == a.species
        })
        .count() as f64
        / stems.len() as f64;
    assert!(same > 0.7, "{same} of nearest neighbours share the species");
}

#[test]
fn stands_that_make_no_trees_say_why() {
    use crate::input::gis::{Feature, Geometry, Value};
    let layer_fields = |fields: &[&str]| -> (Layer, StandFields) {
        let layer = Layer::for_tests(fields);
        let f = StandFields::find(&layer, &StandOptions::default()).unwrap();
        (layer, f)
    };
    let (_, fields) = layer_fields(&["stand_id", "species", "stems_ha", "mean_height"]);
    let feature = |geometry: Geometry, values: Vec<Value>| Feature { index: 1, geometry, values };
    let ok = feature(
        Geometry::Polygons(vec![vec![square(0.0, 0.0, 100.0)]]),
        vec![Value::Text("7b".into()), Value::Text("Larix decidua".into()), Value::Float(300.0), Value::Float(18.0)],
    );
    let (s, _) = read_stand(&ok, &fields, &StandOptions::default(), false).unwrap();
    assert_eq!((s.id.as_str(), s.stems_ha, s.height), ("7b", 300.0, Some((18.0, false))));
    assert_eq!(s.assumed.iter().map(|a| a.0).collect::<Vec<_>>(), ["no DBH: heights ±8 % about the stand's"]);
    let why = |f: Feature| read_stand(&f, &fields, &StandOptions::default(), false).unwrap_err();
    let mut absurd = ok.clone();
    absurd.values[2] = Value::Float(1e7);
    assert!(why(absurd).contains("stems/ha is past"));
    let mut nameless = ok.clone();
    nameless.values[1] = Value::Null;
    assert!(why(nameless).contains("no species"));
    let mut flat = ok.clone();
    flat.geometry = Geometry::Polygons(vec![vec![vec![[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [0.0, 0.0]]]]);
    assert!(why(flat).contains("no area"));
    let mut nan = ok.clone();
    nan.geometry = Geometry::Polygons(vec![vec![vec![[f64::NAN, 0.0], [10.0, 0.0], [0.0, 10.0]]]]);
    assert!(why(nan).contains("non-finite"));
    let mut huge = ok.clone();
    huge.geometry = Geometry::Polygons(vec![vec![square(0.0, 0.0, 100_000.0)]]);
    assert!(why(huge).contains("split it"));
    let mut point = ok;
    point.geometry = Geometry::Points(vec![[0.0, 0.0, f64::NAN]]);
    assert!(why(point).contains("not a polygon"));
}
