//! Search by attributes in the browser (`v.query` in web/sylva.js fetches
//! the files; these match them) and the tile walk that lists them.

use wasm_bindgen::prelude::*;

use super::js_err;

/// Search by attributes, for `v.query` (web/sylva.js fetches the files):
/// parses `schema` (the manifest's `attributes` as JSON, or `null`) and
/// `filter`, and says whether a tile whose `attribute_codes` are `ranges`
/// (JSON, or `null`) may hold a match.
///
/// # Errors
/// A filter that does not fit the scene (the message says why).
#[wasm_bindgen(js_name = queryMayMatch)]
pub fn query_may_match(schema: &str, filter: &str, ranges: &str) -> Result<bool, JsValue> {
    let (schema, filter) = query_parse(schema, filter)?;
    let ranges: Option<Vec<Option<[u32; 2]>>> = serde_json::from_str(ranges).map_err(js_err)?;
    Ok(filter.may_match(schema.as_ref(), ranges.as_deref()))
}

/// Matches one tile (its bytes, ids and attribute sidecar, as fetched) and
/// returns `{count, ids, bounds, tiles: 1, skipped: 0}` as JSON, at most
/// `limit` ids.
///
/// # Errors
/// A filter that does not fit the scene, or a file that does not decode.
#[wasm_bindgen(js_name = queryTile)]
#[allow(clippy::too_many_arguments)]
pub fn query_tile(
    schema: &str,
    filter: &str,
    species: u32,
    tile: &[u8],
    ids: &[u8],
    attr: Option<Vec<u8>>,
    url: &str,
    limit: usize,
) -> Result<String, JsValue> {
    let (schema, filter) = query_parse(schema, filter)?;
    let attr_url = crate::format::attributes::attributes_url(url);
    let files = [url, "ids", attr_url.as_str()];
    let mut result = crate::scene::query::QueryResult::default();
    crate::scene::query::query_tile(
        schema.as_ref(),
        &filter,
        species,
        [tile, ids],
        attr.as_deref(),
        files,
        limit,
        &mut result,
    )
    .map_err(js_err)?;
    Ok(result.to_json().to_string())
}

/// The walk over a scene's tiles for `v.query` (web/sylva.js fetches each node
/// it names): the same walker and checks as `sylva query`
/// ([`crate::format::index::TileWalk`]).
#[wasm_bindgen(js_name = TileWalk)]
pub struct WebTileWalk {
    walk: Option<crate::format::index::TileWalk>,
    schema: String,
    species: u32,
}

#[wasm_bindgen(js_class = TileWalk)]
impl WebTileWalk {
    /// Starts a walk from the manifest's bytes (`scene.json` as fetched).
    ///
    /// # Errors
    /// A manifest that does not decode (the decoder checks every URL in it).
    #[wasm_bindgen(constructor)]
    pub fn new(manifest: &[u8]) -> Result<WebTileWalk, JsValue> {
        let m = crate::format::Manifest::decode("scene.json", manifest).map_err(js_err)?;
        Ok(Self {
            schema: serde_json::to_string(&m.attributes).map_err(js_err)?,
            species: u32::try_from(m.species.len()).unwrap_or(u32::MAX),
            walk: Some(crate::format::index::TileWalk::new(&m)),
        })
    }

    /// The manifest's attribute schema as JSON (`null` without), for `queryMayMatch` and `queryTile`.
    #[must_use]
    pub fn schema(&self) -> String {
        self.schema.clone()
    }

    /// Species in the scene, for `queryTile`.
    #[must_use]
    pub fn species(&self) -> u32 {
        self.species
    }

    /// The index node to fetch next (relative to `scene.json`), or undefined
    /// when done; throws for a node that must not be fetched (met before, one
    /// more than declared, deeper than declared).
    ///
    /// # Errors
    /// That node, named.
    pub fn next(&self) -> Result<Option<String>, JsValue> {
        let Some(w) = self.walk.as_ref() else { return Ok(None) };
        w.next_url().map(|u| u.map(str::to_string)).map_err(js_err)
    }

    /// Takes the bytes of the node `next` named.
    ///
    /// # Errors
    /// A node that does not decode, is reached twice, or is more than the manifest declares.
    pub fn feed(&mut self, bytes: &[u8]) -> Result<(), JsValue> {
        self.walk.as_mut().ok_or_else(|| js_err("the walk is finished"))?.feed(bytes).map_err(js_err)
    }

    /// Every tile as JSON `[{url, ids_url, attr_url, attribute_codes}]`, row order; ends the walk.
    ///
    /// # Errors
    /// Called twice.
    pub fn tiles(&mut self) -> Result<String, JsValue> {
        let walk = self.walk.take().ok_or_else(|| js_err("the walk is finished"))?;
        let tiles: Vec<serde_json::Value> = walk
            .finish()
            .iter()
            .map(|t| {
                serde_json::json!({
                    "url": t.url,
                    "ids_url": t.ids_url,
                    "attr_url": crate::format::attributes::attributes_url(&t.url),
                    "attribute_codes": t.attribute_codes,
                })
            })
            .collect();
        Ok(serde_json::Value::Array(tiles).to_string())
    }
}

fn query_parse(
    schema: &str,
    filter: &str,
) -> Result<(Option<crate::format::attributes::AttributeSchema>, crate::scene::query::Filter), JsValue> {
    let schema: Option<crate::format::attributes::AttributeSchema> = serde_json::from_str(schema).map_err(js_err)?;
    if let Some(s) = &schema {
        s.validate().map_err(js_err)?;
    }
    let filter: serde_json::Value = serde_json::from_str(filter).map_err(js_err)?;
    let filter = crate::scene::query::Filter::parse(schema.as_ref(), &filter).map_err(js_err)?;
    Ok((schema, filter))
}
