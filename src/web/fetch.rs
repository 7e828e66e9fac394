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

async fn fetch_bytes(url: &str, range: Option<crate::scene::fetch::ByteRange>) -> Result<Vec<u8>, FetchError> {
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
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
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

    fn poll(&mut self) -> Done {
        std::mem::take(&mut *self.done.borrow_mut())
    }

    fn in_flight(&self) -> usize {
        self.pending.get() + self.done.borrow().len()
    }
}
