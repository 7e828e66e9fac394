//! The trees' ids and attributes of resident tiles, fetched when a style or a
//! pick needs them.

use super::*;

impl<F: Fetcher> SceneStream<F> {
    /// Fetch the ids (`ids`) and attributes (`attributes`, for scenes with
    /// them) of resident tiles' trees, as a style needs them; neither: stop
    /// and forget them.
    pub fn set_tree_data(&mut self, ids: bool, attributes: bool) {
        let wanted = (ids || attributes, attributes);
        if self.tree_data == wanted {
            return;
        }
        // Attributes newly wanted: tiles read without them are read again.
        let again = !wanted.0 || (wanted.1 && !self.tree_data.1);
        self.tree_data = wanted;
        if again {
            for t in &mut self.tiles {
                if let TileState::Resident { data, .. } = t {
                    *data = TreeDataLoad::None;
                }
            }
        }
    }

    /// Every resident tile: its number, its range in the instance pool and its
    /// trees' ids and attributes once they arrived (with [`Self::set_tree_data`]).
    #[allow(clippy::type_complexity)]
    pub fn resident_tree_data(
        &self,
    ) -> impl Iterator<Item = (usize, std::ops::Range<u32>, &[[u32; 3]], TreeDataState<'_>)> + '_ {
        self.tiles.iter().enumerate().filter_map(|(t, state)| match state {
            TileState::Resident { slot, data, prefix, .. } => {
                let state = match data {
                    TreeDataLoad::Ready(d) => TreeDataState::Ready(d),
                    TreeDataLoad::Broken => TreeDataState::Broken,
                    _ => TreeDataState::Pending,
                };
                Some((t, slot.instances.clone(), prefix.runs.as_slice(), state))
            }
            TileState::NotResident(_) => None,
        })
    }

    /// Requests the ids and attributes of resident tiles that lack them, the
    /// wanted (nearest) tiles first, within the in-flight budget.
    pub(super) fn request_tree_data(&mut self) {
        if !self.tree_data.0 {
            return;
        }
        let attributes = self.tree_data.1 && self.manifest.as_ref().is_some_and(|m| m.attributes.is_some());
        let due = |d: &TreeDataLoad| matches!(d, TreeDataLoad::None | TreeDataLoad::Failed(_));
        let order: Vec<usize> = self
            .wanted
            .iter()
            .copied()
            .chain(0..self.tiles.len())
            .filter(|&t| matches!(&self.tiles[t], TileState::Resident { data, .. } if due(data)))
            .collect();
        for t in order {
            if self.fetcher.in_flight() + 2 > self.config.max_in_flight.max(2) {
                break;
            }
            let TileState::Resident { data, .. } = &mut self.tiles[t] else { continue };
            let attempt = match data {
                TreeDataLoad::None => 0,
                TreeDataLoad::Failed(n) => *n,
                _ => continue,
            };
            *data = TreeDataLoad::Loading { attempt, ids: None, codes: if attributes { None } else { Some(None) } };
            let entry = &self.index.tiles[t];
            let ids_url = join(&self.base, &entry.ids_url);
            let attr_url = join(&self.base, &crate::format::attributes::attributes_url(&entry.url));
            let id = self.fetcher.start(&ids_url);
            self.requests.insert(id, Target::TreeData(t, false));
            self.stats.requests += 1;
            if attributes {
                let id = self.fetcher.start(&attr_url);
                self.requests.insert(id, Target::TreeData(t, true));
                self.stats.requests += 1;
            }
        }
    }

    pub(super) fn on_tree_data(&mut self, t: usize, attributes: bool, result: Result<Vec<u8>, FetchError>) {
        let Some(m) = &self.manifest else { return };
        let entry = &self.index.tiles[t];
        let url = if attributes {
            join(&self.base, &crate::format::attributes::attributes_url(&entry.url))
        } else {
            join(&self.base, &entry.ids_url)
        };
        let TileState::Resident { slot, data, prefix, .. } = &mut self.tiles[t] else { return };
        let TreeDataLoad::Loading { attempt, ids, codes } = data else { return };
        let attempt = *attempt;
        // The sidecars hold every tree of the tile, also when only a prefix is resident.
        let count = if prefix.batches.is_empty() {
            slot.instances.len()
        } else {
            prefix.batches.iter().map(|b| b.instance_count as usize).sum()
        };
        let decoded = result.map_err(|e| e.to_string()).and_then(|bytes| {
            if attributes {
                let schema = m.attributes.as_ref().ok_or("the scene has no attributes")?;
                let c = crate::format::attributes::decode_attributes(&url, &bytes, schema, count)
                    .map_err(|e| e.to_string())?;
                *codes = Some(Some(c));
            } else {
                let v = crate::format::decode_tree_ids(&url, &bytes).map_err(|e| e.to_string())?;
                if v.numbers.len() != count {
                    return Err(format!("{url}: {} ids for {count} trees", v.numbers.len()));
                }
                *ids = Some(v);
            }
            Ok(())
        });
        match decoded {
            Err(message) => {
                // (The other sidecar's answer, if still to come, finds the tile no longer loading.)
                let retrying = attempt + 1 < TREE_DATA_ATTEMPTS;
                *data = if retrying { TreeDataLoad::Failed(attempt + 1) } else { TreeDataLoad::Broken };
                if !retrying {
                    self.give_up(&url, &message);
                }
                self.events.push(StreamEvent::Failed { url, message, retrying });
            }
            Ok(()) => {
                if let TreeDataLoad::Loading { ids: Some(_), codes: Some(_), .. } = data {
                    if let TreeDataLoad::Loading { ids: Some(ids), codes: Some(codes), .. } = std::mem::take(data) {
                        *data = TreeDataLoad::Ready(std::sync::Arc::new(TreeData { ids, codes }));
                    }
                }
            }
        }
    }
}
