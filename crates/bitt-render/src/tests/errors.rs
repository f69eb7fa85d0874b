//! Bad input is rejected with clear errors.

use crate::RenderError;
use crate::cpu::{Fragments, interpolate, interpolate_backward, rasterize, rasterize_backward};

fn tri() -> Vec<[f32; 4]> {
    vec![
        [-0.5, -0.5, 0.0, 1.0],
        [0.5, -0.5, 0.0, 1.0],
        [0.0, 0.5, 0.0, 1.0],
    ]
}

#[test]
fn out_of_range_face_index_is_rejected() {
    let err = rasterize(&tri(), &[[0, 1, 2], [0, 3, 1]], 8, 8).unwrap_err();
    assert_eq!(
        err,
        RenderError::InvalidIndex {
            face: 1,
            index: 3,
            num_vertices: 3
        }
    );
    assert!(
        err.to_string().contains("face 1 references vertex 3"),
        "{err}"
    );
}

#[test]
fn non_finite_position_is_rejected() {
    let mut clip = tri();
    clip[2][1] = f32::NAN;
    let err = rasterize(&clip, &[[0, 1, 2]], 8, 8).unwrap_err();
    assert!(
        matches!(err, RenderError::NonFinitePosition { vertex: 2, .. }),
        "{err}"
    );
    clip[2][1] = f32::INFINITY;
    assert!(rasterize(&clip, &[[0, 1, 2]], 8, 8).is_err());
}

#[test]
fn zero_size_image_is_rejected() {
    for (w, h) in [(0, 8), (8, 0), (0, 0)] {
        let err = rasterize(&tri(), &[[0, 1, 2]], w, h).unwrap_err();
        assert_eq!(
            err,
            RenderError::ZeroSizeImage {
                width: w,
                height: h
            }
        );
    }
    assert!(matches!(
        rasterize(&tri(), &[], usize::MAX, 2),
        Err(RenderError::ImageTooLarge { .. })
    ));
}

#[test]
fn wrong_buffer_lengths_and_layouts_are_rejected() {
    let clip = tri();
    let faces = [[0u32, 1, 2]];
    let frags = rasterize(&clip, &faces, 8, 8).unwrap();
    let err = rasterize_backward(&clip, &faces, &frags, &[[0.0; 3]; 5], None).unwrap_err();
    assert_eq!(
        err,
        RenderError::BufferLength {
            what: "grad_bary",
            expected: 64,
            actual: 5
        }
    );
    let gb = vec![[0.0; 3]; 64];
    assert!(rasterize_backward(&clip, &faces, &frags, &gb, Some(&[0.0; 3])).is_err());
    let mut bad = frags.clone();
    bad.depth.pop();
    assert!(matches!(
        rasterize_backward(&clip, &faces, &bad, &gb, None),
        Err(RenderError::BufferLength {
            what: "fragments.depth",
            ..
        })
    ));
    // Fragments naming a face that does not exist.
    assert!(matches!(
        rasterize_backward(&clip, &[], &frags, &gb, None),
        Err(RenderError::InvalidFragmentFace { .. })
    ));
    let attrs = [0.0f32; 9];
    assert_eq!(
        interpolate(&attrs, 2, &faces, &frags).unwrap_err(),
        RenderError::BadAttributeLayout {
            len: 9,
            num_attrs: 2
        }
    );
    assert!(interpolate(&attrs, 0, &faces, &frags).is_err());
    assert!(matches!(
        interpolate(&attrs[..6], 3, &faces, &frags),
        Err(RenderError::InvalidIndex {
            face: 0,
            index: 2,
            num_vertices: 2
        })
    ));
    assert!(matches!(
        interpolate_backward(&attrs, 3, &faces, &frags, &[0.0; 10]),
        Err(RenderError::BufferLength {
            what: "grad_out",
            ..
        })
    ));
    let empty = Fragments::empty(8, 8);
    assert!(
        interpolate(&attrs, 3, &faces, &empty)
            .unwrap()
            .iter()
            .all(|&x| x == 0.0)
    );
}
