//! The node graph of a glTF scene, checked before it is walked.
//!
//! glTF requires nodes to form disjoint trees, but the JSON can say anything: a
//! node that lists itself as its child (the walk would never end), a loop
//! through several nodes, or a chain of nodes that each list the next one
//! several times (a DAG 24 levels deep expands to 2^24 copies). Cycles are
//! refused; a node reached twice is instanced like a glTF viewer would, but the
//! expansion is counted first (without expanding it) and bounded.

use anyhow::{bail, Result};

/// Most node instances a model may expand to (a tree has tens to thousands).
pub const MAX_NODE_INSTANCES: u64 = 100_000;

/// The root nodes of the scene to import: the default scene, else the first,
/// else every node that is nobody's child.
pub fn roots(doc: &gltf::Document) -> Vec<usize> {
    if let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) {
        return scene.nodes().map(|n| n.index()).collect();
    }
    let mut is_child = vec![false; doc.nodes().len()];
    for node in doc.nodes() {
        for child in node.children() {
            is_child[child.index()] = true;
        }
    }
    (0..is_child.len()).filter(|&i| !is_child[i]).collect()
}

/// `node 3 ("Branch")`, for messages.
pub fn describe(doc: &gltf::Document, index: usize) -> String {
    match doc.nodes().nth(index).and_then(|n| n.name().map(str::to_string)) {
        Some(name) => format!("node {index} ({name:?})"),
        None => format!("node {index}"),
    }
}

/// Checks that the graph below `roots` has no cycle and expands to at most
/// [`MAX_NODE_INSTANCES`] node instances.
///
/// # Errors
/// A cycle, or an expansion over the budget; the message names the node.
pub fn check(doc: &gltf::Document, roots: &[usize]) -> Result<()> {
    let children: Vec<Vec<usize>> = doc.nodes().map(|n| n.children().map(|c| c.index()).collect()).collect();
    for (i, kids) in children.iter().enumerate() {
        if kids.contains(&i) {
            bail!("{} lists itself as its own child: glTF nodes must form trees", describe(doc, i));
        }
    }
    // Iterative depth-first walk from every node: 0 unseen, 1 on the path, 2 done.
    // `instances[n]` = 1 + the instances of its children, saturating.
    let mut state = vec![0u8; children.len()];
    let mut instances = vec![0u64; children.len()];
    for start in 0..children.len() {
        if state[start] != 0 {
            continue;
        }
        let mut stack = vec![(start, 0usize)];
        state[start] = 1;
        while let Some(top) = stack.last_mut() {
            let node = top.0;
            if let Some(&child) = children[node].get(top.1) {
                top.1 += 1;
                match state[child] {
                    0 => {
                        state[child] = 1;
                        stack.push((child, 0));
                    }
                    1 => bail!(
                        "{} is its own descendant (through {}): glTF nodes must form trees",
                        describe(doc, child),
                        describe(doc, node)
                    ),
                    _ => {}
                }
            } else {
                state[node] = 2;
                instances[node] =
                    children[node].iter().fold(1u64, |sum, &c| sum.saturating_add(instances[c])).min(u64::MAX / 2);
                stack.pop();
            }
        }
    }
    let total = roots.iter().fold(0u64, |sum, &r| sum.saturating_add(instances[r]));
    if total > MAX_NODE_INSTANCES {
        // Name the node where the expansion passes the budget: over it, with
        // every child under it.
        let culprit = (0..children.len())
            .filter(|&n| instances[n] > MAX_NODE_INSTANCES)
            .find(|&n| children[n].iter().all(|&c| instances[c] <= MAX_NODE_INSTANCES));
        match culprit {
            Some(n) => bail!(
                "{} expands to {} node instances (at most {MAX_NODE_INSTANCES}): a tree model has far fewer; check \
                 for nodes listed by several parents (glTF nodes must form trees)",
                describe(doc, n),
                if instances[n] >= u64::MAX / 2 { "more than 10^18".to_string() } else { instances[n].to_string() }
            ),
            None => bail!(
                "the scene expands to {total} node instances (at most {MAX_NODE_INSTANCES}): nodes are listed \
                 by several parents; glTF nodes must form trees"
            ),
        }
    }
    Ok(())
}
