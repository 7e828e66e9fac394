//! Canopy raster: any bytes → Ok or an error, never a panic; what decodes
//! re-encodes to the same bytes (a version 1 raster: as version 2 with a
//! tallest ratio of 1, which decodes to the same raster), and every cell reads back.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva::format::canopy::Canopy;

fuzz_target!(|data: &[u8]| {
    if let Ok(c) = Canopy::decode("fuzz.cnpy", data) {
        if data[4..6] == [1, 0] {
            assert_eq!(c.tallest_ratio, 1.0);
            assert_eq!(Canopy::decode("again.cnpy", &c.encode()).unwrap(), c);
        } else {
            assert_eq!(c.encode(), data);
        }
        for y in 0..c.cells {
            for x in 0..c.cells {
                let cell = c.cell(x, y);
                assert!(cell.cover >= 0.0 && cell.cover <= 1.0);
            }
        }
        let _ = (c.mean_cover(), c.cell_m());
    }
});
