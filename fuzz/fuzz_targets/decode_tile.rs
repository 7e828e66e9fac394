//! Tile decoder: any bytes → Ok or a DecodeError; never a panic, never a huge allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The first byte picks the species count the manifest would give.
    let species = u32::from(data.first().copied().unwrap_or(0));
    if let Ok(tile) = sylva::format::Tile::decode("fuzz.tile", data.get(1..).unwrap_or(&[]), species) {
        // A valid tile re-encodes to the same bytes (a version 2 tile without
        // crown aspects as version 1), and every instance decodes to finite values.
        let mut expected = data[1..].to_vec();
        if tile.version() == 1 {
            expected[4] = 1;
        }
        assert_eq!(tile.encode(), expected);
        for b in &tile.batches {
            let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
            for i in &tile.instances[run] {
                let d = i.decode(b);
                assert!(d.position_m.iter().all(|v| v.is_finite()) || b.origin_m.iter().any(|o| o.abs() > 1e30));
                assert!(d.aspect.is_finite() && d.aspect > 0.0);
            }
        }
    }
});
