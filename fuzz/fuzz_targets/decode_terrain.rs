//! Terrain tile decoder: any bytes → Ok or a DecodeError; never a panic, never a
//! huge allocation; a tile that decodes re-encodes to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(tile) = sylva::format::TerrainTile::decode("fuzz.terr", data) {
        assert_eq!(tile.encode(), data);
        let side = tile.side();
        for j in 0..side {
            for i in 0..side {
                if let Some(h) = tile.height(i, j) {
                    assert!(h.is_finite());
                }
            }
        }
    }
});
