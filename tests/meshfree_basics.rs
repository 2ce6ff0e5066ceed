//! Meshfree reference path (SPEC §10): RPIM reproduction and interpolation, small-strain
//! stiffness, tangent consistency, bad input. Small discs: these run in debug builds.

use sdem::meshfree::{
    DiscModel, DiscNodes, Hyperelastic, HyperelasticLaw, MeshfreeError, Multipliers, NodeDensity,
    Rpim, Wall, add_wall_contacts,
};

fn quadratic(c: [f64; 6], x: [f64; 2]) -> (f64, f64, f64) {
    let (u, v) = (x[0], x[1]);
    (
        c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * v * v + c[5] * u * v,
        c[1] + 2.0 * c[3] * u + c[5] * v,
        c[2] + 2.0 * c[4] * v + c[5] * u,
    )
}

#[test]
fn rpim_reproduces_the_polynomial_basis_at_arbitrary_points() {
    // Expectation: any field of [1, x, y, x^2, y^2, xy] is interpolated exactly (value and
    // gradient), at points that are neither nodes nor Gauss points.
    let nodes = DiscNodes::disc(0.5, NodeDensity::new(32)).unwrap();
    let rpim = Rpim::new(&nodes.positions).unwrap();
    let coeffs = [0.3, -1.2, 0.7, 2.1, -0.4, 1.5];
    let mut worst: f64 = 0.0;
    for k in 0..200 {
        // A deterministic scatter over the disc (golden-angle spiral), boundary included.
        let r = 0.5 * ((k as f64 + 0.5) / 200.0).sqrt();
        let t = k as f64 * 2.399_963_229_728_653;
        let x = [r * t.cos(), r * t.sin()];
        let sf = rpim.shape_functions(x).unwrap();
        let (v, gx, gy) = sf.interpolate(|j| quadratic(coeffs, nodes.positions[j]).0);
        let (ev, egx, egy) = quadratic(coeffs, x);
        worst = worst
            .max((v - ev).abs())
            .max((gx - egx).abs())
            .max((gy - egy).abs());
        // Partition of unity and of its derivative.
        let s: f64 = sf.value.iter().sum();
        assert!((s - 1.0).abs() < 1e-10);
    }
    assert!(worst < 1e-9, "worst reproduction error {worst:e}");
}

#[test]
fn rpim_shape_functions_are_interpolating() {
    // Expectation: Phi_i(X_k) = delta_ik (Kronecker delta) at every field node.
    let nodes = DiscNodes::disc(0.5, NodeDensity::new(24)).unwrap();
    let rpim = Rpim::new(&nodes.positions).unwrap();
    let mut worst: f64 = 0.0;
    for (k, x) in nodes.positions.iter().enumerate() {
        let sf = rpim.shape_functions(*x).unwrap();
        assert!(sf.nodes.contains(&k));
        for (i, &j) in sf.nodes.iter().enumerate() {
            let expect = if j == k { 1.0 } else { 0.0 };
            worst = worst.max((sf.value[i] - expect).abs());
        }
    }
    assert!(worst < 1e-9, "worst Kronecker error {worst:e}");
}

fn small_model(law: HyperelasticLaw, nu: f64) -> DiscModel {
    let mat = Hyperelastic::new(law, 1.0, nu, 1.0).unwrap();
    DiscModel::disc(0.5, NodeDensity::new(24), mat).unwrap()
}

#[test]
fn unloaded_tangent_is_linear_plane_strain_elasticity() {
    // Expectation: for a uniform strain u = eps X, the stiffness gives the exact strain energy
    // (1/2) eps:C:eps * area of plane-strain linear elasticity, the internal forces of a tiny
    // uniform strain equal K u, and rigid translations carry no force.
    for law in [
        HyperelasticLaw::NeoHookean,
        HyperelasticLaw::SaintVenantKirchhoff,
    ] {
        let (e, nu) = (1.0, 0.3);
        let model = small_model(law, nu);
        let k = model.initial_stiffness().unwrap();
        let (lam, mu) = (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        );
        let (exx, eyy, exy) = (0.01, -0.004, 0.003);
        let mut u = vec![0.0; model.dofs()];
        for (a, x) in model.nodes.positions.iter().enumerate() {
            u[2 * a] = exx * x[0] + exy * x[1];
            u[2 * a + 1] = exy * x[0] + eyy * x[1];
        }
        let ku = k.mul_vec(&u);
        let energy: f64 = 0.5 * u.iter().zip(&ku).map(|(a, b)| a * b).sum::<f64>();
        let (sxx, syy, sxy) = (
            lam * (exx + eyy) + 2.0 * mu * exx,
            lam * (exx + eyy) + 2.0 * mu * eyy,
            2.0 * mu * exy,
        );
        let exact = 0.5 * (sxx * exx + syy * eyy + 2.0 * sxy * exy) * model.mesh.area;
        assert!(
            (energy - exact).abs() < 1e-10 * exact,
            "{law:?}: {energy} vs {exact}"
        );
        // Stress at every Gauss point of a tiny uniform strain: the analytic stress.
        let s = 1e-6;
        let us: Vec<f64> = u.iter().map(|v| v * s).collect();
        let mut f = vec![0.0; model.dofs()];
        model.internal(&us, &mut f, None).unwrap();
        for (fi, kui) in f.iter().zip(&ku) {
            assert!((fi - s * kui).abs() < 1e-6 * s, "{law:?}: f_int != K u");
        }
        for g in 0..model.gauss_count() {
            let fg = model.deformation_gradient(g, &us);
            let r = model.material.response(fg).unwrap();
            assert!((r.p[0][0] - s * sxx).abs() < 1e-4 * s * sxx.abs());
            assert!((r.p[1][1] - s * syy).abs() < 1e-4 * s * syy.abs());
            assert!((r.p[0][1] - s * sxy).abs() < 1e-4 * s * sxy.abs());
        }
        // Rigid translation: no force.
        let t: Vec<f64> = (0..model.dofs())
            .map(|i| if i % 2 == 0 { 1.0 } else { -2.0 })
            .collect();
        let kt = k.mul_vec(&t);
        assert!(kt.iter().all(|v| v.abs() < 1e-10));
    }
}

#[test]
fn tangent_matches_finite_differences_of_the_residual_with_contact() {
    // Expectation: the consistent tangent (bulk + wall contact with its tributary-length term)
    // is the derivative of the residual at a large deformation.
    let model = small_model(HyperelasticLaw::NeoHookean, 0.3);
    let n = model.dofs();
    let mut u = vec![0.0; n];
    for (a, x) in model.nodes.positions.iter().enumerate() {
        u[2 * a] = -0.08 * x[0] + 0.05 * x[1] * x[1];
        u[2 * a + 1] = -0.12 * x[1] + 0.03 * x[0] * x[1];
    }
    let walls = [
        Wall::new([0.0, -0.435], [0.0, 1.0]),
        Wall::new([0.455, 0.0], [-1.0, 0.0]),
    ];
    let mut mult = Multipliers::zeros(2, model.nodes.boundary_count);
    mult.values[0][18] = 0.01;
    mult.values[0][19] = 0.02;
    let k_c = 3.0;
    let eval = |u: &[f64], t: Option<&mut sdem::meshfree::Dense>| {
        let mut r = vec![0.0; n];
        let mut t = t;
        model.internal(u, &mut r, t.as_deref_mut()).unwrap();
        add_wall_contacts(&model, u, &walls, &mult, k_c, &mut r, t);
        r
    };
    let mut k = sdem::meshfree::Dense::zeros(n);
    eval(&u, Some(&mut k));
    let h = 1e-7;
    let mut worst: f64 = 0.0;
    let scale = k.data.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    for j in (0..n).step_by(7).chain(0..8) {
        let mut up = u.clone();
        let mut um = u.clone();
        up[j] += h;
        um[j] -= h;
        let (rp, rm) = (eval(&up, None), eval(&um, None));
        for i in 0..n {
            worst = worst.max(((rp[i] - rm[i]) / (2.0 * h) - k.get(i, j)).abs());
        }
    }
    assert!(
        worst < 1e-5 * scale,
        "worst tangent error {worst:e} (scale {scale:e})"
    );
}

#[test]
fn bad_input_gets_clear_errors() {
    // Expectation: nu >= 0.5, too few nodes for 20-neighbour supports, bad densities: errors
    // that say what is wrong, no panic.
    let e = Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, 0.5, 1.0).unwrap_err();
    assert!(e.to_string().contains("Poisson"), "{e}");
    let nodes = DiscNodes::disc(0.5, NodeDensity::new(8)).unwrap();
    assert!(nodes.len() < 21);
    let mat = Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, 0.3, 1.0).unwrap();
    let e = DiscModel::from_nodes(nodes, mat).unwrap_err();
    assert!(matches!(e, MeshfreeError::TooCoarse { .. }));
    assert!(e.to_string().contains("too coarse"), "{e}");
    assert!(DiscNodes::disc(0.5, NodeDensity::new(30)).is_err());
    assert!(DiscNodes::disc(-1.0, NodeDensity::new(32)).is_err());
}
