//! The shooting solve over links: progressive refinement (a Southwell iteration) on the hierarchy, in the order
//! a device relights (M. Cohen, S. Chen, J. Wallace, D. Greenberg, "A progressive refinement approach to fast
//! radiosity image generation", SIGGRAPH 1988; on a hierarchy, Hanrahan, Salzman, Aupperle 1991, section 4).
//!
//! Every node with links keeps its unshot radiosity: the area-weighted mean change of the leaves below it since
//! the node last shot (at the start, its emission's mean). Shooting node `s` sends `f * unshot_s` over each of
//! its links as irradiance at the receiver `r`; every leaf below `r` reflects `rho * f * unshot_s` (a cluster
//! receives isotropically, as in the gathering solve's push), and the change reaches, area-weighted, the radiosity
//! and the unshot radiosity of every node below and above `r` (the pull). A leaf's transfer runs through its own
//! links and all its ancestors', so each level must shoot the leaf's change over its own links: hence one unshot
//! value per node. With `R(n) = sum A_l rho_l` over the leaves `l` below `n`, an irradiance `h` at `r` changes
//! node `n` below `r` by `h R(n) / A_n` and node `m` above `r` by `h R(r) / A_m`, so a shot costs the receivers'
//! subtrees and their depths, not a leaf walk per ancestor.
//!
//! Order: rounds; each shoots, in index order, every node whose unshot power `A max_c |unshot|` is at least
//! [`ROUND_SHARE`] of the round's largest (the largest residuals first, as Southwell's rule, without a priority
//! queue). It stops when the total unshot power over all nodes with links is at most `tolerance` times the
//! total power `sum A max_c B` of the leaves. The fixed point is the gathering solve's: at convergence every
//! leaf has received, through every link on its chain, the sender's full radiosity.

use super::link::Link;
use super::solve::{grouped, pull, Group, NodeRadiosity};
use super::span::Span;
use super::tree::{Tree, NONE};
use crate::rgb::{max_channel, Rgb};

/// A node shoots in a round when its unshot power is at least this share of the round's largest.
pub const ROUND_SHARE: f64 = 1.0 / 64.0;

/// Shooting rounds with emission `e` and reflectance `rho` per node (zero on clusters) until the unshot power is
/// at most `tolerance` of the total, or `max_rounds` ran. The returned `sweeps` counts shots, `change` is the remaining unshot power
/// over the total (infinite or NaN if it diverged).
pub(super) fn shoot(
    tree: &Tree,
    links: &[Link],
    (e, rho): (&[Rgb], &[Rgb]),
    tolerance: f64,
    max_rounds: usize,
) -> NodeRadiosity {
    let n = tree.nodes.len();
    let e = e.to_vec();
    // Outgoing links per node, as (receiver, form factor at the receiver).
    let (start, out) = grouped(n, links, Group::BySender);
    // R(n): area times reflectance summed over the leaves below (children have larger indices).
    let mut reflecting = vec![Rgb::ZERO; n];
    for k in (0..n).rev() {
        let node = &tree.nodes[k];
        if node.children.is_empty() {
            reflecting[k] = node.area * rho[k];
        }
        if node.parent != NONE {
            let r = reflecting[k];
            reflecting[node.parent as usize] += r;
        }
    }
    let mut b = e.clone();
    let mut spans = vec![Span::ZERO; n];
    pull(tree, &mut b, &e, &mut spans);
    let shoots = |k: usize| start[k + 1] > start[k];
    let mut unshot: Vec<Rgb> = (0..n).map(|k| if shoots(k) { b[k] } else { Rgb::ZERO }).collect();
    let power = |unshot: &[Rgb], k: usize| tree.nodes[k].area * max_channel(unshot[k].abs());
    let mut stack = Vec::new();
    let (mut shots, mut rounds) = (0usize, 0usize);
    let change = loop {
        let total: f64 = (0..n)
            .filter(|&k| tree.nodes[k].children.is_empty())
            .map(|k| tree.nodes[k].area * max_channel(b[k]))
            .sum();
        let left: f64 = (0..n).map(|k| power(&unshot, k)).sum();
        // Overflowed power is divergence, not a change of 0.
        let change = if !total.is_finite() || !left.is_finite() {
            f64::NAN
        } else if total > 0.0 {
            left / total
        } else {
            0.0
        };
        if !change.is_finite() || change <= tolerance || rounds == max_rounds {
            break change;
        }
        rounds += 1;
        let largest = (0..n).map(|k| power(&unshot, k)).fold(0.0, f64::max);
        for s in 0..n {
            if !(shoots(s) && power(&unshot, s) >= ROUND_SHARE * largest && power(&unshot, s) > 0.0) {
                continue;
            }
            let d = std::mem::replace(&mut unshot[s], Rgb::ZERO);
            shots += 1;
            for &(r, f) in &out[start[s]..start[s + 1]] {
                let h = f * d;
                // The receiver's subtree: every node below gains h R(n) / A_n.
                stack.push(r);
                while let Some(m) = stack.pop() {
                    let node = &tree.nodes[m as usize];
                    let delta = h * reflecting[m as usize] / node.area;
                    b[m as usize] += delta;
                    if shoots(m as usize) {
                        unshot[m as usize] += delta;
                    }
                    stack.extend_from_slice(&node.children);
                }
                // Its ancestors: h R(r) / A_m each.
                let gained = h * reflecting[r as usize];
                let mut m = tree.nodes[r as usize].parent;
                while m != NONE {
                    let delta = gained / tree.nodes[m as usize].area;
                    b[m as usize] += delta;
                    if shoots(m as usize) {
                        unshot[m as usize] += delta;
                    }
                    m = tree.nodes[m as usize].parent;
                }
            }
        }
    };
    // Area means and spans from the leaves (the running sums above drift by rounding only).
    pull(tree, &mut b, &e, &mut spans);
    NodeRadiosity { b, spans, sweeps: shots, change }
}

#[cfg(test)]
mod tests {
    use super::super::link::{expand_self, Limits, RefineCounts};
    use super::super::pieces::refine;
    use super::super::solve::{emission as node_emission, emission_bound, reflectance, solve, Incoming};
    use super::super::testing::cornell_polygons;
    use super::super::tree::Tree;
    use super::shoot;
    use crate::formfactor::occluder_scene;
    use crate::rgb::{max_channel, Rgb};

    /// The Cornell box's tree and direct-light links at a coarse bound.
    fn direct_links() -> (Tree, Vec<super::super::link::Link>) {
        let (roots, lighting, rules) = cornell_polygons();
        let emission = lighting.default_emission();
        let caster = occluder_scene(&roots, true).unwrap();
        let mut tree = Tree::new(&rules, &roots, &lighting.rho, &emission);
        let brightest =
            roots.iter().zip(&emission).map(|(p, e)| p.area * max_channel(*e)).fold(0.0, f64::max);
        let area: f64 = roots.iter().map(|p| p.area).sum();
        let limits = Limits {
            threshold: 3e-3 * brightest,
            min_area: 1e-4 * area,
            max_nodes: 100_000,
            max_links: usize::MAX,
            pieces: 1,
            sender_weight: 0.0,
        };
        let estimator = super::super::link::Estimator::for_tests(&rules, &caster);
        let mut spans = emission_bound(&tree);
        let (mut candidates, mut links, mut counts) = (Vec::new(), Vec::new(), RefineCounts::default());
        expand_self(&tree, 0, &mut candidates);
        refine(&mut tree, &estimator, &mut spans, &limits, candidates, &mut links, &mut counts).unwrap();
        assert!(links.len() > 100, "{} links", links.len());
        (tree, links)
    }

    /// `sum A |a - b| / sum A a` over the leaves (largest channel).
    fn relative_difference(tree: &Tree, a: &[Rgb], b: &[Rgb]) -> f64 {
        let (mut diff, mut total) = (0.0, 0.0);
        for (k, node) in tree.nodes.iter().enumerate() {
            if node.children.is_empty() {
                diff += node.area * max_channel((a[k] - b[k]).abs());
                total += node.area * max_channel(a[k]);
            }
        }
        diff / total
    }

    /// On the Cornell box's direct-light links, shooting and gathering reach the same radiosity: both stop at a
    /// residual of `tol` of the total power, and the error left after a residual `r` is at most `r / (1 - q)`,
    /// `q` the operator's contraction per sweep (observed: the gathering went from a change of at most 1 to
    /// `tol` in its sweeps); so the two differ by at most `2 tol / (1 - q)` relative, area-weighted. (The row
    /// sums do not bound `q` here: a hierarchy's leaf row sums exceed 1 where ancestors' averages overstate.)
    #[test]
    fn shooting_reaches_the_gathering_answer() {
        let (tree, links) = direct_links();
        let tol = 1e-10;
        let e = node_emission(&tree);
        let rho = reflectance(&tree);
        let gathered = solve(&tree, &Incoming::new(tree.nodes.len(), &links), (&e, &rho), None, tol, 100_000);
        let shot = shoot(&tree, &links, (&e, &rho), tol, 100_000);
        assert!(gathered.change <= tol && shot.change <= tol, "{} {}", gathered.change, shot.change);
        // The iteration's contraction per sweep, as observed: from a change of at most 1 to `tol` in `sweeps`.
        let q = tol.powf(1.0 / gathered.sweeps as f64);
        let difference = relative_difference(&tree, &gathered.b, &shot.b);
        let allowed = 2.0 * tol / (1.0 - q);
        assert!(difference <= allowed, "relative difference {difference:.3e} > {allowed:.3e}");
        eprintln!(
            "relative difference {difference:.3e}, allowed {allowed:.3e}, {} sweeps, {} shots",
            gathered.sweeps, shot.sweeps
        );
        // Shooting did real work: more shots than nodes that emit.
        assert!(shot.sweeps > 1, "{} shots", shot.sweeps);
    }

    /// A gathering solve started warm (from an earlier answer, here the cold answer scaled by 0.9 and known only
    /// for the first half of the nodes, the rest starting at their parents') reaches the cold answer within
    /// the same bound as shooting does (`2 tol / (1 - q)`), in fewer sweeps.
    #[test]
    fn a_warm_gathering_solve_reaches_the_cold_answer_sooner() {
        let (tree, links) = direct_links();
        let tol = 1e-10;
        let (e, rho) = (node_emission(&tree), reflectance(&tree));
        let cold = solve(&tree, &Incoming::new(tree.nodes.len(), &links), (&e, &rho), None, tol, 100_000);
        let start: Vec<_> = cold.b[..tree.nodes.len() / 2].iter().map(|b| 0.9 * *b).collect();
        let warm =
            solve(&tree, &Incoming::new(tree.nodes.len(), &links), (&e, &rho), Some(&start), tol, 100_000);
        assert!(cold.change <= tol && warm.change <= tol, "{} {}", cold.change, warm.change);
        let q = tol.powf(1.0 / cold.sweeps as f64);
        let difference = relative_difference(&tree, &cold.b, &warm.b);
        let allowed = 2.0 * tol / (1.0 - q);
        assert!(difference <= allowed, "relative difference {difference:.3e} > {allowed:.3e}");
        assert!(warm.sweeps < cold.sweeps, "{} sweeps warm, {} cold", warm.sweeps, cold.sweeps);
    }
}
