//! Steady-state frames allocate nothing in Sylva's own per-frame code: the
//! streaming decisions and the frame's CPU work (its own process: a counting
//! global allocator).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn steady_state_frames_allocate_nothing_in_streaming() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    let fixture = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
    // (Half the size it was, a quarter of the pixels: what is counted is streaming,
    // whose choices follow the view's pixels per metre, not the frame.)
    let pools = sylva::render::forest::PoolConfig { instances: 1 << 16, batches: 1 << 12, items: 1 << 17, species: 8 };
    let mut off = sylva::offscreen::OffscreenScene::open(fixture.to_str().unwrap(), 160, 90, pools).unwrap();
    off.load_view(&sylva::camera::Camera::default(), 30.0);
    let count = |f: &mut dyn FnMut()| {
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        f();
        ALLOCATIONS.load(Ordering::Relaxed) - before
    };
    // The medium view (billboards and impostors at this size) and the close view
    // (mesh levels streamed): every representation's streaming path in steady state.
    use sylva::offscreen::NamedView;
    for view in [NamedView::Medium, NamedView::Close] {
        let cam = off.named_camera(view, 30.0).unwrap();
        off.load_view(&cam, 30.0);
        for _ in 0..3 {
            off.render(&cam, false);
        }
        let mut stream = 0;
        let mut frame = 0;
        for _ in 0..20 {
            stream += count(&mut || {
                off.update_stream(&cam);
            });
            frame += count(&mut || {
                off.render(&cam, false);
            });
        }
        eprintln!("{view:?}, per frame: streaming {} allocations, render {}", stream / 20, frame / 20);
        // The steady state is a view of the forest: tiles resident, trees drawn.
        let stats = off.render(&cam, true);
        assert!(
            stats.tiles_resident > 0 && stats.instances.values().sum::<u64>() > 100,
            "{view:?}: {:?}",
            stats.instances
        );
        if view == NamedView::Close {
            let meshes =
                stats.instances.get("mesh0").copied().unwrap_or(0) + stats.instances.get("mesh1").copied().unwrap_or(0);
            assert!(meshes > 0, "the close view streams mesh levels: {:?}", stats.instances);
        }
        assert_eq!(stream, 0, "{view:?}: streaming decisions allocate in steady state");
    }
}
