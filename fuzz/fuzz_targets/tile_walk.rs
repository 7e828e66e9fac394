//! The index walk the browser's `query` and `sylva query` share
//! (`sylva::format::index::TileWalk`): a manifest and any node bytes → tiles or
//! an error, never a panic, and never more fetches than the manifest declares
//! nodes. The input's first two bytes split it: the manifest (JSON), then node
//! bodies separated by NUL, handed out in turn to whatever URL the walk asks for
//! (so a node can come back as its own child).
#![no_main]
use libfuzzer_sys::fuzz_target;
use sylva::format::index::TileWalk;
use sylva::format::Manifest;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let split = usize::from(u16::from_le_bytes([data[0], data[1]]));
    let rest = &data[2..];
    let (manifest, nodes) = rest.split_at(split.min(rest.len()));
    let Ok(m) = Manifest::decode("scene.json", manifest) else { return };
    let declared = m.index.as_ref().map_or(0, |i| i.nodes.max(1));
    let bodies: Vec<&[u8]> = nodes.split(|&b| b == 0).collect();
    let mut walk = TileWalk::new(&m);
    let mut fetches = 0u64;
    // A node is checked before it is fetched: an error there ends the walk.
    while let Ok(Some(_)) = walk.next_url() {
        fetches += 1;
        assert!(fetches <= declared, "more fetches than declared nodes");
        let body = bodies.get((fetches as usize - 1) % bodies.len().max(1)).copied().unwrap_or(&[]);
        if walk.feed(body).is_err() {
            return;
        }
    }
    let _ = walk.finish();
});
