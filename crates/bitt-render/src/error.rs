//! Error type and shared input validation.

/// Largest supported image side, in pixels.
pub const MAX_IMAGE_SIDE: usize = 1 << 24;

/// Errors reported by the rasterizer and interpolation entry points.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// The image has zero width or zero height.
    #[error("image size must be non-zero, got width {width} x height {height}")]
    ZeroSizeImage {
        /// Requested width in pixels.
        width: usize,
        /// Requested height in pixels.
        height: usize,
    },
    /// The image is larger than [`MAX_IMAGE_SIDE`] on a side.
    #[error("image size {width}x{height} exceeds the maximum of {MAX_IMAGE_SIDE} pixels per side")]
    ImageTooLarge {
        /// Requested width in pixels.
        width: usize,
        /// Requested height in pixels.
        height: usize,
    },
    /// A face references a vertex that does not exist.
    #[error("face {face} references vertex {index}, but only {num_vertices} vertices exist")]
    InvalidIndex {
        /// Index of the offending face.
        face: usize,
        /// The out-of-range vertex index.
        index: u32,
        /// Number of vertices available.
        num_vertices: usize,
    },
    /// More faces than a per-pixel `i32` face id can address.
    #[error(
        "{num_faces} faces exceed the maximum of {} addressable by i32 face ids",
        i32::MAX
    )]
    TooManyFaces {
        /// Number of faces given.
        num_faces: usize,
    },
    /// A clip-space position contains NaN or infinity.
    #[error("clip position of vertex {vertex} is not finite: {value:?}")]
    NonFinitePosition {
        /// Index of the offending vertex.
        vertex: usize,
        /// Its clip-space position (x, y, z, w).
        value: [f32; 4],
    },
    /// A buffer has the wrong number of elements.
    #[error("buffer `{what}` has {actual} elements, expected {expected}")]
    BufferLength {
        /// Which buffer.
        what: &'static str,
        /// Expected element count.
        expected: usize,
        /// Actual element count.
        actual: usize,
    },
    /// A fragment buffer names a face that does not exist.
    #[error("fragment at pixel {pixel} names face {face}, but only {num_faces} faces exist")]
    InvalidFragmentFace {
        /// Linear pixel index (`row * width + col`).
        pixel: usize,
        /// The stored face id.
        face: i32,
        /// Number of faces available.
        num_faces: usize,
    },
    /// `num_attrs` is zero or does not divide the attribute buffer.
    #[error("attribute buffer of {len} values cannot hold {num_attrs} channels per vertex")]
    BadAttributeLayout {
        /// Length of the attribute buffer.
        len: usize,
        /// Requested channels per vertex.
        num_attrs: usize,
    },
    /// A texture has zero channels.
    #[error("texture must have at least one channel")]
    ZeroChannels,
    /// A texture coordinate of a sampled (unmasked) pixel contains NaN or infinity.
    #[error("uv of pixel {pixel} is not finite: {value:?}")]
    NonFiniteUv {
        /// Index of the offending pixel.
        pixel: usize,
        /// Its texture coordinate (u, v).
        value: [f32; 2],
    },
    /// A tensor argument has the wrong shape.
    #[error("tensor `{what}` has shape {actual:?}, expected {expected}")]
    TensorShape {
        /// Which argument.
        what: &'static str,
        /// The expected shape, in words (e.g. `[V, 4]` with V = 778).
        expected: String,
        /// The actual shape.
        actual: Vec<usize>,
    },
    /// A camera cannot be used for projection.
    #[error("unusable camera: {0}")]
    BadCamera(String),
    /// A light has non-finite or out-of-range values.
    #[error("unusable light: {0}")]
    BadLight(String),
    /// A UV layout does not fit the mesh it is used with.
    #[error("texture layout does not fit the mesh: {0}")]
    BadLayout(String),
    /// Reading a tensor back from its device failed.
    #[error("cannot read tensor `{what}` back from the device: {reason}")]
    TensorRead {
        /// Which argument.
        what: &'static str,
        /// The backend's message.
        reason: String,
    },
}

/// Checks the image size and returns the pixel count.
pub(crate) fn check_image(width: usize, height: usize) -> Result<usize, RenderError> {
    if width == 0 || height == 0 {
        return Err(RenderError::ZeroSizeImage { width, height });
    }
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(RenderError::ImageTooLarge { width, height });
    }
    width
        .checked_mul(height)
        .ok_or(RenderError::ImageTooLarge { width, height })
}

/// Checks that every clip position is finite.
pub(crate) fn check_positions(clip: &[[f32; 4]]) -> Result<(), RenderError> {
    match clip.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        Some(vertex) => Err(RenderError::NonFinitePosition {
            vertex,
            value: clip[vertex],
        }),
        None => Ok(()),
    }
}

/// Checks that every face index is below `num_vertices` and that face ids fit in `i32`.
pub(crate) fn check_faces(faces: &[[u32; 3]], num_vertices: usize) -> Result<(), RenderError> {
    if faces.len() > i32::MAX as usize {
        return Err(RenderError::TooManyFaces {
            num_faces: faces.len(),
        });
    }
    for (face, tri) in faces.iter().enumerate() {
        if let Some(&index) = tri.iter().find(|&&i| i as usize >= num_vertices) {
            return Err(RenderError::InvalidIndex {
                face,
                index,
                num_vertices,
            });
        }
    }
    Ok(())
}

/// Checks a buffer length.
pub(crate) fn check_len(
    what: &'static str,
    actual: usize,
    expected: usize,
) -> Result<(), RenderError> {
    if actual == expected {
        Ok(())
    } else {
        Err(RenderError::BufferLength {
            what,
            expected,
            actual,
        })
    }
}
