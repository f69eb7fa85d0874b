//! The scene light as plain values (the paper's 12 numbers, section 3.1) and the text users
//! give for it (`--light`): parsed and checked here, below burn, so the fuzz targets reach
//! them. The renderer's tensor light (`bitt_render::scene::PointLight`) is built from these.

/// The 12 numbers of the paper's light parameterisation (section 3.1), in its order:
/// ambient colour, diffuse colour, specular colour, location.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LightValues {
    /// Ambient colour (RGB).
    pub ambient: [f32; 3],
    /// Diffuse colour (RGB).
    pub diffuse: [f32; 3],
    /// Specular colour (RGB).
    pub specular: [f32; 3],
    /// Location (world coordinates).
    pub location: [f32; 3],
}

impl Default for LightValues {
    /// The reference renderer's default light (`build_light`): ambient 0.5, diffuse 0.1,
    /// specular 0.3, at (0, 1, 0).
    fn default() -> Self {
        Self {
            ambient: [0.5; 3],
            diffuse: [0.1; 3],
            specular: [0.3; 3],
            location: [0.0, 1.0, 0.0],
        }
    }
}

impl LightValues {
    /// From the 12-number vector (ambient, diffuse, specular, location).
    pub fn from_array(v: [f32; 12]) -> Self {
        let part = |i: usize| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
        Self {
            ambient: part(0),
            diffuse: part(1),
            specular: part(2),
            location: part(3),
        }
    }

    /// The 12-number vector (ambient, diffuse, specular, location).
    pub fn to_array(&self) -> [f32; 12] {
        let mut out = [0.0; 12];
        for (i, part) in [self.ambient, self.diffuse, self.specular, self.location]
            .iter()
            .enumerate()
        {
            out[3 * i..3 * i + 3].copy_from_slice(part);
        }
        out
    }

    /// The first part with a value that is not finite, as `"name is [...]"`.
    ///
    /// # Errors
    /// That part, named.
    pub fn check_finite(&self) -> Result<(), String> {
        for (name, part) in [
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
            ("location", self.location),
        ] {
            if part.iter().any(|x| !x.is_finite()) {
                return Err(format!("{name} is {part:?}"));
            }
        }
        Ok(())
    }
}

/// A light as users write it: JSON `{"ambient": [r, g, b], "diffuse": [r, g, b],
/// "specular": [r, g, b], "location": [x, y, z]}`; `source` names it in errors (`--light` or
/// the file). Every value finite, no colour negative, and not every colour 0: light adds to
/// the image, so those would render black (issue 38).
///
/// # Errors
/// Not such JSON, or a value out of range, named.
pub fn parse_light(text: &str, source: &str) -> Result<LightValues, String> {
    let light: LightValues = serde_json::from_str(text).map_err(|e| {
        format!(
            "{source}: expected JSON {{\"ambient\": [r, g, b], \"diffuse\": [r, g, b], \
             \"specular\": [r, g, b], \"location\": [x, y, z]}}: {e}"
        )
    })?;
    light
        .check_finite()
        .map_err(|e| format!("{source}: {e} (every light value must be finite)"))?;
    let colours = [
        ("ambient", light.ambient),
        ("diffuse", light.diffuse),
        ("specular", light.specular),
    ];
    if let Some((name, part)) = colours.iter().find(|(_, p)| p.iter().any(|&x| x < 0.0)) {
        return Err(format!(
            "{source}: {name} is {part:?}; a light's colours are 0 or more"
        ));
    }
    if colours.iter().all(|(_, p)| p.iter().all(|&x| x == 0.0)) {
        return Err(format!(
            "{source}: ambient, diffuse and specular are all 0: that light renders black"
        ));
    }
    Ok(light)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lights_that_render_nothing_are_named() {
        let ok = r#"{"ambient": [0.5, 0.5, 0.5], "diffuse": [0.1, 0.1, 0.1],
            "specular": [0.3, 0.3, 0.3], "location": [0, 1, 0]}"#;
        let light = parse_light(ok, "--light").unwrap();
        assert_eq!(light, LightValues::default());
        assert_eq!(LightValues::from_array(light.to_array()), light);
        for (text, expected) in [
            (
                ok.replace("[0.5, 0.5, 0.5]", "[-0.5, 0.5, 0.5]"),
                "ambient is [-0.5, 0.5, 0.5]",
            ),
            (
                ok.replace("0.5", "0")
                    .replace("0.1", "0")
                    .replace("0.3", "0"),
                "all 0: that light renders black",
            ),
            (ok.replace("[0, 1, 0]", "[0, 1]"), "expected JSON"),
            ("[]".to_string(), "expected JSON"),
        ] {
            let e = parse_light(&text, "l.json").unwrap_err();
            assert!(e.starts_with("l.json: ") && e.contains(expected), "{e}");
        }
        let inf = LightValues {
            location: [0.0, f32::INFINITY, 0.0],
            ..LightValues::default()
        };
        assert_eq!(
            inf.check_finite().unwrap_err(),
            "location is [0.0, inf, 0.0]"
        );
    }
}
