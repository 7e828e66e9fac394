//! Tile decoder: any bytes → Ok or a DecodeError; never a panic, never a huge allocation.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The first byte picks the species count the manifest would give.
    let species = u32::from(data.first().copied().unwrap_or(0));
    let bytes = data.get(1..).unwrap_or(&[]);
    if let Ok(tile) = sylva::format::Tile::decode("fuzz.tile", bytes, species) {
        // A valid tile re-encodes to the same bytes: versions 3 and 4 in prefix
        // levels; versions 1 and 2 in the old layout (a version 2 tile without
        // crown aspects as version 1). Every instance decodes to finite values.
        if bytes[4] >= 3 {
            // (This build writes 15 levels of version 4, 7 of version 3; other
            // level counts read but re-encode otherwise.)
            let at = 32 + 80 * tile.batches.len();
            let levels = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
            if bytes[4] == 4 && levels == sylva::format::tile::TILE_LEVELS {
                assert_eq!(tile.encode(), bytes);
            } else if bytes[4] == 3 && levels == sylva::format::tile::TILE_LEVELS_V3 {
                assert_eq!(tile.encode_v3(), bytes);
            }
        } else {
            let mut expected = bytes.to_vec();
            expected[4] = tile.whole_version() as u8;
            assert_eq!(tile.encode_whole(), expected);
        }
        for b in &tile.batches {
            let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
            for i in &tile.instances[run] {
                let d = i.decode(b);
                assert!(d.position_m.iter().all(|v| v.is_finite()) || b.origin_m.iter().any(|o| o.abs() > 1e30));
                assert!(d.aspect.is_finite() && d.aspect > 0.0);
            }
        }
    }
    // A prefix: each batch's first trees, mapped back to the tile's order within it.
    if let Ok(p) = sylva::format::Tile::decode_prefix("fuzz.tile", bytes, species) {
        assert!(p.levels >= 1 && p.levels <= p.of);
        let held: u32 = p.tile.batches.iter().map(|b| b.instance_count).sum();
        assert_eq!(held as usize, p.tile.instances.len());
        let whole: u64 = p.tile.batches.iter().map(|b| u64::from(b.whole_count())).sum();
        let runs = p.runs();
        for i in 0..held {
            assert!(u64::from(sylva::format::tile::whole_index(&runs, i)) < whole);
        }
    }
});
