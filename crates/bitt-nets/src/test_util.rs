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
