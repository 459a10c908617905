//! `radiosity check --method hierarchical`: the device's hierarchical solver on a hierarchical table (core's format
//! version 5), its error traced to its sources as the flat check traces a flat table's (module docs of
//! [`crate::check`], "Hierarchical tables").

use radiosity_core::HierTable;

use super::device::{device_part, Answers, DeviceTable};
use super::{check_options, max_power, CheckError, CheckOptions, CheckReport};
use crate::bake::bake_hierarchy;
use crate::evaluate::{self, Component, EvaluateError, QUANTIZATION};
use crate::hierarchy::{dense_on_leaves, HierarchicalSolution};
use crate::lighting::PatchLighting;
use crate::metrics;
use crate::montecarlo::continuous_reference;
use crate::reference::{TransferVectors, MAX_DENSE_PATCHES};
use crate::rgb::Rgb;
use crate::scene::Scene;

/// The name of the component that compares the hierarchical answer with the dense answer of its own leaves.
pub const HIERARCHY_LINKS: &str = "hierarchy (links)";
/// The name of the component that compares the table's own system with the hierarchical solve.
pub const TABLE_CLOSURE: &str = "table closure";

/// What a hierarchical check compares every frame with.
const EXACT_HIER: &str = "hierarchical f64 solve (its transfer vectors relit)";

/// Bakes `solution` (the hierarchical solve of `scene`) into a hierarchical table with `options.bits`-bit codes,
/// runs core's hierarchical solver on it frame by frame as the firmware does, and decomposes the error (module
/// docs of [`crate::check`], "Hierarchical tables"). The flat table's settings (`threshold`, `ff_factor`,
/// `row_sum_tolerance`) do not apply and are not used; a [`CheckOptions::codec`] is refused (the hierarchical
/// bake takes a code width).
///
/// # Errors
/// See [`CheckError`]; also when the solution carries no per-source answer ([`HierarchicalSolution::transfer`]).
pub fn check_hierarchical(
    scene: &Scene,
    solution: &HierarchicalSolution,
    options: &CheckOptions,
) -> Result<CheckReport, CheckError> {
    check_options(options)?;
    if options.codec.is_some() {
        return Err(CheckError::Options(
            "a codec other than the code width applies to flat tables only (the hierarchical bake takes --bits)"
                .into(),
        ));
    }
    let transfer = solution.transfer.as_ref().ok_or_else(|| {
        CheckError::Options("the hierarchical solution has no per-source answer to relight".into())
    })?;
    let lighting = PatchLighting::new(scene, &solution.leaves);
    let baked = bake_hierarchy(scene, solution, options.bits, false)?;
    let table = HierTable::parse(&baked.table)
        .map_err(|error| CheckError::BadTable { path: "<baked>".into(), error })?;
    // Everything below is in the table's leaf order.
    let order = &baked.solution_leaf;
    let in_table = |v: &[Rgb]| -> Vec<Rgb> { order.iter().map(|&l| v[l]).collect() };
    let area: Vec<f64> = order.iter().map(|&l| solution.leaves[l].area).collect();
    let exact = TransferVectors {
        b_static: in_table(&transfer.b_static),
        t: transfer.t.iter().map(|t| in_table(t)).collect(),
        residual: transfer.residual,
        sweeps: transfer.sweeps,
    };
    let hierarchy = in_table(&solution.b);

    let discretization = match &options.continuous {
        Some(settings) => {
            let continuous = continuous_reference(scene, settings)?;
            Some(evaluate::discretization(&solution.leaves, &solution.b, &continuous)?)
        }
        None => None,
    };
    let mut components: Vec<Component> = discretization.iter().map(|d| d.component.clone()).collect();
    if solution.leaves.len() <= MAX_DENSE_PATCHES {
        let dense = dense_on_leaves(scene, solution)?
            .relight(&lighting.default_intensity)
            .map_err(|source| EvaluateError::Reference { what: "dense answer of the leaves", source })?;
        components.push(Component {
            name: HIERARCHY_LINKS.into(),
            compares:
                "hierarchical f64 solve vs dense f64 solve of the same leaves (every leaf-to-leaf form \
                       factor)"
                    .into(),
            error: metrics::compare(&hierarchy, &in_table(&dense), &area)?,
        });
    }
    components.push(Component {
        name: TABLE_CLOSURE.into(),
        compares:
            "f64 solve of the table's system (chain cap; closed scenes: self-links) vs hierarchical f64 \
                   solve"
                .into(),
        error: metrics::compare(&baked.radiosity, &hierarchy, &area)?,
    });
    let decoded = baked.decoded_radiosity(&solution.network)?;
    components.push(Component {
        name: QUANTIZATION.into(),
        compares: "f64 solve of the decoded table vs f64 solve of the table's system".into(),
        error: metrics::compare(&decoded, &baked.radiosity, &area)?,
    });
    let light_groups: Vec<String> =
        lighting.dynamic_groups.iter().map(|&g| scene.light_groups[g].name.clone()).collect();
    let answers = Answers {
        exact: &exact,
        exact_is: EXACT_HIER,
        default_intensity: &lighting.default_intensity,
        max_power: max_power(&in_table(&solution.emission), &area),
        device: &decoded,
        area: &area,
        light_groups: &light_groups,
    };
    let report = device_part(DeviceTable::Hier(&table), baked.table.len(), &answers, options, components)?;
    Ok(CheckReport { discretization, ..report })
}
