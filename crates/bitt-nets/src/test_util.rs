//! Helpers shared by this crate's unit tests beyond the workspace's kit (`bitt-testkit`).

use bitt_testkit::{assert_close, devices, to_vec};
use burn::tensor::Tensor;

/// Every float parameter's gradient, in visiting order (empty where there is none).
pub(crate) fn param_grads<M: burn::module::Module>(
    module: &M,
    grads: &burn::tensor::Gradients,
) -> Vec<Vec<f32>> {
    struct Collect<'a> {
        grads: &'a burn::tensor::Gradients,
        out: Vec<Vec<f32>>,
    }
    impl burn::module::ModuleVisitor for Collect<'_> {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            let g = param.val().grad(self.grads).map(to_vec).unwrap_or_default();
            self.out.push(g);
        }
    }
    let mut c = Collect {
        grads,
        out: Vec::new(),
    };
    module.visit(&mut c);
    c.out
}

/// [`assert_close`] over lists of gradients.
pub(crate) fn assert_all_close(a: &[Vec<f32>], b: &[Vec<f32>], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: counts differ");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(!y.is_empty(), "{what}: parameter {i} has no gradient");
        assert_close(x, y, tol, &format!("{what}: parameter {i}"));
    }
}

/// `forward(module, input)` on every backend but flex (ndarray, wgpu: burn's layers) equals
/// its value on flex, where `module` and `input` live, within `tol`.
pub(crate) fn assert_same_as_flex<M: burn::module::Module, const D: usize, const E: usize>(
    module: &M,
    input: &Tensor<D>,
    forward: impl Fn(M, Tensor<D>) -> Tensor<E>,
    tol: f32,
    what: &str,
) {
    let on_flex = to_vec(forward(module.clone(), input.clone()));
    for (name, device) in devices().into_iter().filter(|(n, _)| *n != "flex") {
        let out = forward(
            module.clone().to_device(&device),
            input.clone().to_device(&device),
        );
        assert_close(
            &to_vec(out),
            &on_flex,
            tol,
            &format!("{what} {name} vs flex"),
        );
    }
}

/// `sum a b`, accumulated in `f64`.
pub(crate) fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(a, b)| f64::from(*a) * f64::from(*b))
        .sum()
}

/// Checks that `dx` and `dw` are the gradients of `<conv(x, w), g>` for a convolution `conv`
/// that is linear in each argument (no bias): `<x, dx> = <w, dw> = <conv(x, w), g>` within
/// `tol[0]` (relative), and at one-hot probes `dx[i] = <conv(e_i, w), g>` within `tol[1]`,
/// `dw[i] = <conv(x, e_i), g>` within `tol[2]` (relative to at least 1).
pub(crate) fn assert_conv_adjoints(
    [x, w, g]: [&[f32]; 3],
    [dx, dw]: [&[f32]; 2],
    conv: impl Fn(&[f32], &[f32]) -> Vec<f32>,
    tol: [f64; 3],
    what: &str,
) {
    let zg = dot(&conv(x, w), g);
    let inner = |a: f64| (a - zg).abs() < tol[0] * zg.abs().max(1.0);
    assert!(inner(dot(x, dx)), "{what}: <x, dx> != <conv(x, w), g>");
    assert!(inner(dot(w, dw)), "{what}: <w, dw> != <conv(x, w), g>");
    let one_hot = |len: usize, i: usize| {
        let mut e = vec![0.0; len];
        e[i] = 1.0;
        e
    };
    for probe in [0, x.len() / 3, x.len() / 2, x.len() - 1] {
        let expect = dot(&conv(&one_hot(x.len(), probe), w), g);
        let got = f64::from(dx[probe]);
        assert!(
            (got - expect).abs() < tol[1] * expect.abs().max(1.0),
            "{what}: dx[{probe}] {got} vs {expect}"
        );
    }
    for probe in [0, w.len() / 2, w.len() - 1] {
        let expect = dot(&conv(x, &one_hot(w.len(), probe)), g);
        let got = f64::from(dw[probe]);
        assert!(
            (got - expect).abs() < tol[2] * expect.abs().max(1.0),
            "{what}: dw[{probe}] {got} vs {expect}"
        );
    }
}
