//! The DEM reader never panics, hangs or allocates without bound on hostile
//! GeoTIFF bytes: it reads a height grid or returns an error, and a grid it
//! reads samples to finite heights or none.
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva_bake::input::dem::Dem;

fuzz_target!(|data: &[u8]| {
    if let Ok(dem) = Dem::read(std::io::Cursor::new(data)) {
        let s = dem.summary();
        let (x, y) = ((s.extent[0] + s.extent[2]) * 0.5, (s.extent[1] + s.extent[3]) * 0.5);
        if let Some(h) = dem.sample(x, y) {
            assert!(h.is_finite());
        }
    }
});
