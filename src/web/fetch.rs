//! The browser's `fetch` as the streamer's [`Fetcher`]: requests started
//! at once, completions queued until polled.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use wasm_bindgen::prelude::*;
use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use crate::scene::{FetchError, Fetcher, RequestId};

type Done = Vec<(RequestId, Result<Vec<u8>, FetchError>)>;

/// Fetches with the browser's `fetch`; completions queue up until polled.
#[derive(Default)]
pub struct WebFetcher {
    next: RequestId,
    pending: Rc<Cell<usize>>,
    done: Rc<RefCell<Done>>,
}

pub(super) async fn fetch_bytes(
    url: &str,
    range: Option<crate::scene::fetch::ByteRange>,
) -> Result<Vec<u8>, FetchError> {
    let transport = |e: JsValue| FetchError::Transport {
        url: url.to_string(),
        message: e.as_string().unwrap_or_else(|| format!("{e:?}")),
    };
    let window = web_sys::window().ok_or_else(|| transport(JsValue::from_str("no window")))?;
    let promise = match range {
        Some((a, b)) => {
            // A single range is a CORS-safelisted header: no preflight on a static host.
            let headers = web_sys::Headers::new().map_err(transport)?;
            headers.set("Range", &format!("bytes={a}-{}", b.max(a + 1) - 1)).map_err(transport)?;
            let init = web_sys::RequestInit::new();
            init.set_headers(&headers);
            window.fetch_with_str_and_init(url, &init)
        }
        None => window.fetch_with_str(url),
    };
    let resp: web_sys::Response = JsFuture::from(promise).await.map_err(transport)?.dyn_into().map_err(transport)?;
    match resp.status() {
        404 => return Err(FetchError::NotFound { url: url.to_string() }),
        s if !(200..300).contains(&s) => return Err(FetchError::Status { url: url.to_string(), status: s }),
        _ => {}
    }
    let buffer = JsFuture::from(resp.array_buffer().map_err(transport)?).await.map_err(transport)?;
    let bytes = js_sys::Uint8Array::new(&buffer);
    // A PNG or JPEG (ground imagery) is decoded by the browser: the wasm module has no decoder.
    let head = bytes.subarray(0, 8.min(bytes.length())).to_vec();
    if range.is_none() && (head.starts_with(b"\x89PNG\r\n\x1a\n") || head.starts_with(&[0xff, 0xd8, 0xff])) {
        return Ok(decode_in_browser(&bytes).await.unwrap_or_else(|_| bytes.to_vec()));
    }
    Ok(bytes.to_vec())
}

/// Most pixels a side an image is decoded at (more than any imagery tile the
/// streamer reads: `crate::format::imagery::decode_image` refuses it then).
const MAX_DECODE_PX: u32 = 8192;

/// The image in `bytes` decoded by the browser (`createImageBitmap`, drawn on an
/// `OffscreenCanvas`, its pixels read back), in a
/// [`crate::format::imagery::DECODED_MAGIC`] container; an error where the
/// browser cannot (then its bytes go on as they came, and the streamer says
/// it cannot decode them).
async fn decode_in_browser(bytes: &js_sys::Uint8Array) -> Result<Vec<u8>, JsValue> {
    let window = web_sys::window().ok_or("no window")?;
    let parts = js_sys::Array::of1(bytes);
    let blob = web_sys::Blob::new_with_u8_array_sequence(&parts)?;
    let bitmap: web_sys::ImageBitmap =
        JsFuture::from(window.create_image_bitmap_with_blob(&blob)?).await?.dyn_into()?;
    let (w, h) = (bitmap.width(), bitmap.height());
    if w == 0 || h == 0 || w > MAX_DECODE_PX || h > MAX_DECODE_PX {
        bitmap.close();
        return Err(JsValue::from_str("image too large"));
    }
    let canvas = web_sys::OffscreenCanvas::new(w, h)?;
    // (Read back at once: a canvas in memory, not one the GPU process draws,
    // which a slow GPU busy with a frame would make wait.)
    let options = js_sys::Object::new();
    js_sys::Reflect::set(&options, &"willReadFrequently".into(), &JsValue::TRUE)?;
    let context: web_sys::OffscreenCanvasRenderingContext2d =
        canvas.get_context_with_context_options("2d", &options)?.ok_or("no 2d context")?.dyn_into()?;
    context.draw_image_with_image_bitmap(&bitmap, 0.0, 0.0)?;
    bitmap.close();
    let data = context.get_image_data(0.0, 0.0, f64::from(w), f64::from(h))?;
    Ok(crate::format::imagery::encode_decoded(w, h, bytes.length(), &data.data()))
}

#[wasm_bindgen]
extern "C" {
    /// The Compression Streams API's inflater (web-sys has it only among its
    /// unstable APIs).
    type DecompressionStream;
    #[wasm_bindgen(constructor, catch)]
    fn new(format: &str) -> Result<DecompressionStream, JsValue>;
}

/// A stored pack's part inflated by the browser (`DecompressionStream`,
/// deflate-raw: no inflater in the wasm module), read chunk by chunk and
/// stopped past `len` bytes; an error unless it is exactly `len` bytes.
pub(super) async fn inflate_in_browser(url: &str, deflated: &[u8], len: u64) -> Result<Vec<u8>, FetchError> {
    let fail = |m: String| FetchError::Transport { url: url.to_string(), message: format!("the stored part {m}") };
    let js = |e: JsValue| fail(format!("does not inflate ({})", e.as_string().unwrap_or_else(|| format!("{e:?}"))));
    let inflater = DecompressionStream::new("deflate-raw").map_err(js)?;
    let blob = web_sys::Blob::new_with_u8_array_sequence(&js_sys::Array::of1(&js_sys::Uint8Array::from(deflated)))
        .map_err(js)?;
    // (A DecompressionStream is a readable/writable pair.)
    let reader: web_sys::ReadableStreamDefaultReader = blob
        .stream()
        .pipe_through(inflater.unchecked_ref())
        .get_reader()
        .dyn_into()
        .map_err(|o: js_sys::Object| js(o.into()))?;
    // (Grown as it inflates: the size the head gives is a bound, not a promise.)
    if len > u64::from(u32::MAX / 2) {
        return Err(fail(format!("of {len} bytes is over what a browser viewer holds")));
    }
    let mut out = Vec::with_capacity(len.min(deflated.len() as u64 * 8) as usize);
    loop {
        let chunk = JsFuture::from(reader.read()).await.map_err(js)?;
        if js_sys::Reflect::get(&chunk, &"done".into()).map_err(js)?.is_truthy() {
            break;
        }
        let value: js_sys::Uint8Array =
            js_sys::Reflect::get(&chunk, &"value".into()).map_err(js)?.dyn_into().map_err(js)?;
        let at = out.len();
        if (at + value.length() as usize) as u64 > len {
            let _ = reader.cancel();
            return Err(fail(format!("inflates to more than {len} bytes")));
        }
        out.resize(at + value.length() as usize, 0);
        value.copy_to(&mut out[at..]);
    }
    if out.len() as u64 != len {
        return Err(fail(format!("inflates to only {} bytes, expected {len}", out.len())));
    }
    Ok(out)
}

impl Fetcher for WebFetcher {
    fn start_range(&mut self, url: &str, range: Option<crate::scene::fetch::ByteRange>) -> RequestId {
        let id = self.next;
        self.next += 1;
        self.pending.set(self.pending.get() + 1);
        let (pending, done, url) = (self.pending.clone(), self.done.clone(), url.to_string());
        wasm_bindgen_futures::spawn_local(async move {
            let result = fetch_bytes(&url, range).await;
            done.borrow_mut().push((id, result));
            pending.set(pending.get() - 1);
        });
        id
    }

    fn start_inflate(&mut self, url: &str, deflated: Vec<u8>, bytes: u64) -> RequestId {
        let id = self.next;
        self.next += 1;
        self.pending.set(self.pending.get() + 1);
        let (pending, done, url) = (self.pending.clone(), self.done.clone(), url.to_string());
        wasm_bindgen_futures::spawn_local(async move {
            let result = inflate_in_browser(&url, &deflated, bytes).await;
            done.borrow_mut().push((id, result));
            pending.set(pending.get() - 1);
        });
        id
    }

    fn poll(&mut self) -> Done {
        std::mem::take(&mut *self.done.borrow_mut())
    }

    fn in_flight(&self) -> usize {
        self.pending.get() + self.done.borrow().len()
    }
}
