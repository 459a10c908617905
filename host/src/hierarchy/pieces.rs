//! Refinement split by receiver subtree into independent pieces, merged into what one piece makes, bit for bit.
//!
//! A pair's refinement stays below its receiver end: splitting the pair replaces it by pairs whose receiver (`a`)
//! is the old receiver or one of its children. So the pairs whose receiver lies in one subtree of a cut through
//! the tree (the **pieces**) can be refined apart from the others, each on its own copy of the tree, and what a
//! pair becomes depends on the pair alone (the estimates' random streams are keyed by the nodes' keys, not by
//! when they were made; the node limit is an error, not a reason to keep a link). The pairs whose receiver lies
//! above the cut are refined first, until every pair left has its receiver in a piece; then the pieces run (in
//! parallel here; on other machines later, since a piece needs only the tree, the spans and its pairs), and the
//! merge takes every piece's new nodes (a node split by two pieces is split the same way in both: its children
//! are the same polygons with the same keys) and links. `link::refine` then orders the new nodes and links by
//! what they are, so the answer is the same for every piece count.

use rayon::prelude::*;

use super::link::{too_many_links, waves, Estimator, Limits, Link, Pair, RefineCounts};
use super::span::Span;
use super::tree::{Tree, NONE};
use super::HierarchyError;
use crate::raycast::RayCaster;

/// Cut nodes per piece: the cut is finer than the piece count so that pieces can be balanced by area.
const CUT_PER_PIECE: usize = 4;

/// The piece of every node of `tree` (as it is now) for `pieces` pieces: the cut is grown from the top by
/// replacing its largest node (by area, then index) that has children by its children, until it holds
/// [`CUT_PER_PIECE`] nodes per piece or no node of it has children; its nodes go to the piece of least area so
/// far, largest first. Nodes above the cut get [`NONE`]; nodes below it their cut ancestor's piece.
fn assign(tree: &Tree, pieces: usize) -> Vec<u32> {
    let mut cut = vec![0u32];
    while cut.len() < CUT_PER_PIECE * pieces {
        let largest = cut
            .iter()
            .enumerate()
            .filter(|(_, &n)| !tree.nodes[n as usize].children.is_empty())
            .max_by(|(_, &x), (_, &y)| {
                tree.nodes[x as usize].area.total_cmp(&tree.nodes[y as usize].area).then(y.cmp(&x))
            })
            .map(|(k, _)| k);
        let Some(k) = largest else { break };
        let n = cut.swap_remove(k);
        cut.extend_from_slice(&tree.nodes[n as usize].children);
    }
    cut.sort_unstable_by(|&x, &y| {
        tree.nodes[y as usize].area.total_cmp(&tree.nodes[x as usize].area).then(x.cmp(&y))
    });
    let mut load = vec![0.0f64; pieces];
    let mut piece = vec![NONE; tree.nodes.len()];
    for &n in &cut {
        let p = (0..pieces).min_by(|&x, &y| load[x].total_cmp(&load[y]).then(x.cmp(&y))).unwrap_or(0);
        load[p] += tree.nodes[n as usize].area;
        piece[n as usize] = p as u32;
    }
    // Parents precede their children: one pass hands every cut node's piece down its subtree.
    for n in 0..tree.nodes.len() {
        let parent = tree.nodes[n].parent;
        if piece[n] == NONE && parent != NONE {
            piece[n] = piece[parent as usize];
        }
    }
    piece
}

/// The piece of node `n` by `piece` ([`assign`] on an older tree): a node made since inherits its parent's.
fn piece_of(tree: &Tree, piece: &[u32], mut n: u32) -> u32 {
    while n as usize >= piece.len() {
        n = tree.nodes[n as usize].parent;
    }
    piece[n as usize]
}

/// What one piece made: its copy of the tree (the nodes it made follow the shared ones), their spans, its links
/// and counts.
struct Piece {
    tree: Tree,
    spans: Vec<Span>,
    links: Vec<Link>,
    counts: RefineCounts,
}

/// Refines `candidates` (each pair on its own: estimated, accepted if within the bound, else replaced by the pairs
/// of the children of its larger splittable end, and so on down), in `limits.pieces` receiver-subtree pieces
/// (`pieces`); appends the accepted links to `links` (also those whose rays all missed: they carry nothing, but
/// the budgets may refine them). What a pair becomes depends on the pair alone (the estimates' streams are keyed
/// by the nodes' keys), so the links and nodes do not depend on the order the pairs were refined in; the nodes
/// made and the links appended are then put in that order's stead in one that depends on them alone (nodes by
/// [`Tree::renumber_from`], links by their ends), so that every piece count gives the same tree and links, bit
/// for bit.
///
/// # Errors
/// [`HierarchyError::Mesh`] if a surface cannot be split; [`HierarchyError::TooManyLinks`] or
/// [`HierarchyError::TooManyNodes`] if refinement would exceed `limits`.
pub(super) fn refine<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<Span>,
    limits: &Limits,
    candidates: Vec<Pair>,
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
) -> Result<(), HierarchyError> {
    let (first_node, first_link) = (tree.nodes.len(), links.len());
    if limits.pieces <= 1 {
        waves(tree, estimator, spans, limits, candidates, links, counts, 0, |_, _| true, &mut Vec::new())?;
    } else {
        in_pieces(tree, estimator, spans, limits, candidates, links, counts)?;
    }
    let order = tree.renumber_from(first_node);
    let mut new_index = vec![NONE; order.len()];
    for (k, &old) in order.iter().enumerate() {
        new_index[old as usize - first_node] = (first_node + k) as u32;
    }
    let moved: Vec<Span> = order.iter().map(|&old| spans[old as usize]).collect();
    spans.truncate(first_node);
    spans.extend(moved);
    let renumber = |n: u32| if (n as usize) < first_node { n } else { new_index[n as usize - first_node] };
    for link in &mut links[first_link..] {
        link.a = renumber(link.a);
        link.b = renumber(link.b);
    }
    links[first_link..].sort_unstable_by_key(|l| (l.a, l.b));
    Ok(())
}

/// [`refine`]'s work in `limits.pieces` pieces: the pairs with their receiver above the cut first, on `tree`,
/// then the pieces in parallel, each on a copy, merged into `tree`, `spans`, `links` and `counts` (the new nodes
/// and links in the pieces' order; [`refine`] orders them).
///
/// # Errors
/// As [`refine`]; the link and node limits are checked in each piece on what it holds, and on the merge.
fn in_pieces<C: RayCaster + ?Sized>(
    tree: &mut Tree,
    estimator: &Estimator<'_, C>,
    spans: &mut Vec<Span>,
    limits: &Limits,
    candidates: Vec<Pair>,
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
) -> Result<(), HierarchyError> {
    let piece = assign(tree, limits.pieces);
    let mut below = Vec::new();
    waves(
        tree,
        estimator,
        spans,
        limits,
        candidates,
        links,
        counts,
        0,
        |t, a| piece_of(t, &piece, a) == NONE,
        &mut below,
    )?;
    let mut buckets = vec![Vec::new(); limits.pieces];
    for pair in below {
        buckets[piece_of(tree, &piece, pair.a) as usize].push(pair);
    }
    let shared = tree.nodes.len();
    let held = links.len();
    let results: Vec<Result<Piece, HierarchyError>> = {
        let (tree, spans) = (&*tree, &*spans);
        buckets
            .into_par_iter()
            .filter(|bucket| !bucket.is_empty())
            .map(|bucket| {
                let mut piece = Piece {
                    tree: tree.clone(),
                    spans: spans.clone(),
                    links: Vec::new(),
                    counts: RefineCounts::default(),
                };
                waves(
                    &mut piece.tree,
                    estimator,
                    &mut piece.spans,
                    limits,
                    bucket,
                    &mut piece.links,
                    &mut piece.counts,
                    held,
                    |_, _| true,
                    &mut Vec::new(),
                )?;
                Ok(piece)
            })
            .collect()
    };
    for result in results {
        merge(tree, spans, links, counts, shared, result?);
    }
    if links.len() > limits.max_links {
        return Err(too_many_links(tree, limits, links.len(), 0, counts));
    }
    if tree.nodes.len() > limits.max_nodes {
        return Err(HierarchyError::TooManyNodes {
            limit: limits.max_nodes,
            nodes: tree.nodes.len(),
            pass: 0,
        });
    }
    Ok(())
}

/// Merges `piece` (made from `tree` when it had `shared` nodes) into `tree`: every split the piece made that
/// `tree` has not (its children moved over with their spans), its links with their ends renumbered, its counts.
fn merge(
    tree: &mut Tree,
    spans: &mut Vec<Span>,
    links: &mut Vec<Link>,
    counts: &mut RefineCounts,
    shared: usize,
    piece: Piece,
) {
    let Piece { tree: mut made, spans: made_spans, links: made_links, counts: made_counts } = piece;
    let mut map = vec![NONE; made.nodes.len() - shared];
    let at = |map: &[u32], n: u32| if (n as usize) < shared { n } else { map[n as usize - shared] };
    // Parents and children as the piece made them, before its nodes move.
    let parents: Vec<u32> = made.nodes[shared..].iter().map(|n| n.parent).collect();
    // The new nodes' children (taken: a moved node gets its own when the loop reaches them); the shared nodes'
    // stay in `made`.
    let children: Vec<Vec<u32>> =
        made.nodes[shared..].iter_mut().map(|n| std::mem::take(&mut n.children)).collect();
    let mut moved: Vec<Option<super::tree::Node>> = made.nodes.drain(shared..).map(Some).collect();
    for j in shared..shared + moved.len() {
        if map[j - shared] != NONE {
            continue;
        }
        // `j` is the first child of a split the piece made (children are made together, in order), and its
        // parent is mapped already (parents are made before their children).
        let parent = parents[j - shared];
        let siblings: &[u32] = if (parent as usize) < shared {
            &made.nodes[parent as usize].children
        } else {
            &children[parent as usize - shared]
        };
        let target = at(&map, parent);
        if tree.nodes[target as usize].children.is_empty() {
            let first = tree.nodes.len() as u32;
            for (k, &c) in siblings.iter().enumerate() {
                let mut node = moved[c as usize - shared].take().expect("a child is moved once");
                node.parent = target;
                tree.nodes.push(node);
                spans.push(made_spans[c as usize]);
                map[c as usize - shared] = first + k as u32;
            }
            tree.nodes[target as usize].children = (first..first + siblings.len() as u32).collect();
        } else {
            for (&c, &e) in siblings.iter().zip(&tree.nodes[target as usize].children) {
                map[c as usize - shared] = e;
            }
        }
    }
    links.extend(made_links.into_iter().map(|l| Link { a: at(&map, l.a), b: at(&map, l.b), ..l }));
    counts.add(&made_counts);
}
