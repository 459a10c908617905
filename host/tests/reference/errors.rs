//! Bad inputs are refused with clear errors, never a panic or a silent result.

use radiosity_host::input::InputError;
use radiosity_host::reference::{
    gauss_seidel, transfer_vectors, DenseLu, GaussSeidelOptions, LightGroupEmission, Method, RadiositySystem,
    ReferenceError,
};
use radiosity_host::rgb::Rgb;

use super::csr;

#[test]
fn bad_inputs_are_refused_with_clear_errors() {
    let dense = vec![vec![0.0, 0.5], vec![0.5, 0.0]];
    let ff = csr(&dense);
    let good = [Rgb::splat(0.5); 2];

    let short = [Rgb::splat(0.5); 1];
    assert_eq!(
        RadiositySystem::new(&short, &ff).unwrap_err(),
        ReferenceError::Input(InputError::LengthMismatch { what: "reflectance", expected: 2, found: 1 })
    );
    let err = RadiositySystem::new(&[Rgb::splat(0.5), Rgb::new(0.5, 1.0, 0.5)], &ff).unwrap_err();
    assert_eq!(err, ReferenceError::ReflectanceOutOfRange { patch: 1, channel: 1, value: 1.0 });
    assert_eq!(err.to_string(), "reflectance of patch 1, channel 1 is 1, outside [0, 1)");
    assert!(matches!(
        RadiositySystem::new(&[Rgb::new(-0.1, 0.5, 0.5), Rgb::splat(0.5)], &ff).unwrap_err(),
        ReferenceError::ReflectanceOutOfRange { patch: 0, channel: 0, .. }
    ));
    assert!(matches!(
        RadiositySystem::new(&[Rgb::splat(0.5), Rgb::new(0.5, 0.5, f64::NAN)], &ff).unwrap_err(),
        ReferenceError::Input(InputError::NonFinite { what: "reflectance", patch: 1, channel: 2, .. })
    ));

    // Form factors: negative, row sum above 1 (NaN and a malformed structure cannot get past
    // `FormFactorMatrix::new`; host/tests/patch.rs tests those).
    let bad = csr(&[vec![0.0, -0.1], vec![0.5, 0.0]]);
    assert!(matches!(
        RadiositySystem::new(&good, &bad).unwrap_err(),
        ReferenceError::FormFactorOutOfRange { .. }
    ));
    let over = csr(&[vec![0.5, 0.5 + 1e-6], vec![0.5, 0.0]]);
    assert!(matches!(
        RadiositySystem::new(&good, &over).unwrap_err(),
        ReferenceError::RowSumTooLarge { row: 0, .. }
    ));
    // ... unless the caller allows that much slack; then rho * row sum must still stay below 1.
    RadiositySystem::with_row_sum_tolerance(&good, &over, 1e-5).unwrap();
    let rho_high = [Rgb::splat(1.0 - 1e-7), Rgb::splat(0.5)];
    assert!(matches!(
        RadiositySystem::with_row_sum_tolerance(&rho_high, &over, 1e-5).unwrap_err(),
        ReferenceError::NotContractive { patch: 0, .. }
    ));

    // Emission: wrong length, NaN.
    let system = RadiositySystem::new(&good, &ff).unwrap();
    let lu = DenseLu::factor(system).unwrap();
    assert!(matches!(
        lu.solve(&[Rgb::ONE]).unwrap_err(),
        ReferenceError::Input(InputError::LengthMismatch { what: "emission", .. })
    ));
    let nan_e = [Rgb::ONE, Rgb::new(0.0, f64::NAN, 0.0)];
    assert!(matches!(
        lu.solve(&nan_e).unwrap_err(),
        ReferenceError::Input(InputError::NonFinite { what: "emission", patch: 1, channel: 1, .. })
    ));
    assert!(matches!(
        gauss_seidel(&system, &nan_e, &GaussSeidelOptions::default()).unwrap_err(),
        ReferenceError::Input(InputError::NonFinite { .. })
    ));

    // Dense size limit: 2 patches with a limit of 1 would need 2^2 * 8 = 32 bytes per channel.
    assert_eq!(
        DenseLu::factor_with_limit(system, 1).unwrap_err(),
        ReferenceError::TooLargeForDense { n: 2, limit: 1, bytes: 32 }
    );

    // Gauss-Seidel: a cap that is too small is an error carrying the residual reached, not a result.
    let e = [Rgb::ONE, Rgb::ZERO];
    let err =
        gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance: 1e-12, max_sweeps: Some(2) }).unwrap_err();
    match err {
        ReferenceError::NotConverged { sweeps: 2, residual, tolerance } => {
            assert!(residual > tolerance && residual.is_finite())
        }
        other => panic!("expected NotConverged after 2 sweeps, got {other:?}"),
    }
    assert_eq!(
        gauss_seidel(&system, &e, &GaussSeidelOptions { tolerance: 0.0, max_sweeps: None }).unwrap_err(),
        ReferenceError::InvalidTolerance(0.0)
    );

    // Light groups: out-of-range group, emission in no group, wrong intensity count.
    let unit = [Rgb::ONE, Rgb::ZERO];
    let zero = [Rgb::ZERO; 2];
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[Some(1), None],
        group_count: 1,
    };
    assert_eq!(
        transfer_vectors(system, &lights, &Method::default()).unwrap_err(),
        ReferenceError::GroupOutOfRange { patch: 0, group: 1, group_count: 1 }
    );
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[None, None],
        group_count: 1,
    };
    assert_eq!(
        transfer_vectors(system, &lights, &Method::default()).unwrap_err(),
        ReferenceError::UngroupedEmission { patch: 0 }
    );
    let lights = LightGroupEmission {
        static_emission: &zero,
        unit_emission: &unit,
        group: &[Some(0), None],
        group_count: 1,
    };
    let tv = transfer_vectors(system, &lights, &Method::default()).unwrap();
    assert!(matches!(
        tv.relight(&[]).unwrap_err(),
        ReferenceError::Input(InputError::LengthMismatch { what: "intensity", .. })
    ));
    assert!(matches!(
        tv.relight(&[Rgb::new(0.0, f64::INFINITY, 0.0)]).unwrap_err(),
        ReferenceError::NonFiniteIntensity { group: 0, channel: 1, .. }
    ));
}
