//! Transfer functions for direct volume rendering: piecewise-linear maps from HU to colour and
//! to opacity, read from a small TOML file or taken from a preset.
//!
//! Opacity is per millimetre: a sample of opacity α seen over a step of Δs mm contributes
//! 1 − (1 − α)^Δs (the renderer's opacity correction), so a picture does not depend on the
//! step length. The presets' control points are 3D Slicer's volume-rendering presets
//! (`Modules/Loadable/VolumeRendering/Resources/presets.xml` in github.com/Slicer/Slicer,
//! BSD-style licence), so that they look as Slicer users know them; Slicer's opacity unit
//! distance is also 1 mm by default.

use std::path::Path;

/// A piecewise-linear transfer function; values outside the control points take the nearest
/// end's value.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// (HU, opacity per mm in [0, 1]), HU increasing.
    pub opacity: Vec<(f32, f32)>,
    /// (HU, linear RGB in [0, 1]), HU increasing.
    pub color: Vec<(f32, [f32; 3])>,
    /// Phong terms of the preset (ambient, diffuse, specular, specular power).
    pub shading: Shading,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub power: f32,
}

impl Default for Shading {
    fn default() -> Self {
        Shading {
            ambient: 0.1,
            diffuse: 0.9,
            specular: 0.2,
            power: 10.0,
        }
    }
}

/// The presets of `--preset` in DVR mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TfPreset {
    CtBone,
    CtBones,
    CtAaa,
    CtMuscle,
    CtLung,
    MipBone,
}

impl TfPreset {
    pub const ALL: [TfPreset; 6] = [
        TfPreset::CtBone,
        TfPreset::CtBones,
        TfPreset::CtAaa,
        TfPreset::CtMuscle,
        TfPreset::CtLung,
        TfPreset::MipBone,
    ];

    pub fn name(self) -> &'static str {
        match self {
            TfPreset::CtBone => "ct-bone",
            TfPreset::CtBones => "ct-bones",
            TfPreset::CtAaa => "ct-aaa",
            TfPreset::CtMuscle => "ct-muscle",
            TfPreset::CtLung => "ct-lung",
            TfPreset::MipBone => "mip-bone",
        }
    }

    /// The preset's function: Slicer's `scalarOpacity` / `colorTransfer` pairs (flattened as
    /// in presets.xml: HU then value(s)) and its shading terms. `mip-bone` is Slicer's CT-MIP.
    pub fn function(self) -> TransferFunction {
        let (opacity, color, ambient, diffuse, specular, power): (&[f32], &[f32], _, _, _, _) =
            match self {
                // Slicer "CT-Bone".
                TfPreset::CtBone => (
                    &[
                        -3024.0, 0.0, -16.4458, 0.0, 641.385, 0.715686, 3071.0, 0.705882,
                    ],
                    &[
                        -3024.0, 0.0, 0.0, 0.0, -16.4458, 0.729412, 0.254902, 0.301961, 641.385,
                        0.905882, 0.815686, 0.552941, 3071.0, 1.0, 1.0, 1.0,
                    ],
                    0.1,
                    0.9,
                    0.2,
                    10.0,
                ),
                // Slicer "CT-Bones".
                TfPreset::CtBones => (
                    &[-1000.0, 0.0, 152.19, 0.0, 278.93, 0.190476, 952.0, 0.2],
                    &[
                        -1000.0, 0.3, 0.3, 1.0, -488.0, 0.3, 1.0, 0.3, 463.28, 1.0, 0.0, 0.0,
                        659.15, 1.0, 0.912535, 0.0374849, 953.0, 1.0, 0.3, 0.3,
                    ],
                    0.2,
                    1.0,
                    0.0,
                    1.0,
                ),
                // Slicer "CT-AAA".
                TfPreset::CtAaa => (
                    &[
                        -3024.0, 0.0, 143.556, 0.0, 166.222, 0.686275, 214.389, 0.696078, 419.736,
                        0.833333, 3071.0, 0.803922,
                    ],
                    &[
                        -3024.0, 0.0, 0.0, 0.0, 143.556, 0.615686, 0.356863, 0.184314, 166.222,
                        0.882353, 0.603922, 0.290196, 214.389, 1.0, 1.0, 1.0, 419.736, 1.0,
                        0.937033, 0.954531, 3071.0, 0.827451, 0.658824, 1.0,
                    ],
                    0.1,
                    0.9,
                    0.2,
                    10.0,
                ),
                // Slicer "CT-Muscle".
                TfPreset::CtMuscle => (
                    &[
                        -3024.0, 0.0, -155.407, 0.0, 217.641, 0.676471, 419.736, 0.833333, 3071.0,
                        0.803922,
                    ],
                    &[
                        -3024.0, 0.0, 0.0, 0.0, -155.407, 0.54902, 0.25098, 0.14902, 217.641,
                        0.882353, 0.603922, 0.290196, 419.736, 1.0, 0.937033, 0.954531, 3071.0,
                        0.827451, 0.658824, 1.0,
                    ],
                    0.1,
                    0.9,
                    0.2,
                    10.0,
                ),
                // Slicer "CT-Lung".
                TfPreset::CtLung => (
                    &[
                        -1000.0, 0.0, -600.0, 0.0, -599.0, 0.15, -400.0, 0.15, -399.0, 0.0, 2952.0,
                        0.0,
                    ],
                    &[
                        -1000.0, 0.3, 0.3, 1.0, -600.0, 0.0, 0.0, 1.0, -530.0, 0.134704, 0.781726,
                        0.0724558, -460.0, 0.929244, 1.0, 0.109473, -400.0, 0.888889, 0.254949,
                        0.0240258, 2952.0, 1.0, 0.3, 0.3,
                    ],
                    0.2,
                    1.0,
                    0.0,
                    1.0,
                ),
                // Slicer "CT-MIP".
                TfPreset::MipBone => (
                    &[-3024.0, 0.0, -637.62, 0.0, 700.0, 1.0, 3071.0, 1.0],
                    &[
                        -3024.0, 0.0, 0.0, 0.0, -637.62, 1.0, 1.0, 1.0, 700.0, 1.0, 1.0, 1.0,
                        3071.0, 1.0, 1.0, 1.0,
                    ],
                    0.1,
                    0.9,
                    0.2,
                    10.0,
                ),
            };
        TransferFunction {
            opacity: opacity.chunks(2).map(|c| (c[0], c[1])).collect(),
            color: color
                .chunks(4)
                .map(|c| (c[0], [c[1], c[2], c[3]]))
                .collect(),
            shading: Shading {
                ambient,
                diffuse,
                specular,
                power,
            },
        }
    }
}

#[inline(always)]
fn lerp_at<T: Copy>(points: &[(f32, T)], hu: f32, mix: impl Fn(T, T, f32) -> T) -> T {
    let i = points.partition_point(|p| p.0 <= hu);
    if i == 0 {
        return points[0].1;
    }
    if i == points.len() {
        return points[i - 1].1;
    }
    let (a, b) = (points[i - 1], points[i]);
    let w = if b.0 > a.0 {
        (hu - a.0) / (b.0 - a.0)
    } else {
        1.0
    };
    mix(a.1, b.1, w)
}

/// The TOML form of a transfer function file.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TfFile {
    /// [[HU, opacity per mm], …]
    opacity: Vec<[f32; 2]>,
    /// [[HU, r, g, b], …]
    color: Vec<[f32; 4]>,
    ambient: Option<f32>,
    diffuse: Option<f32>,
    specular: Option<f32>,
    specular_power: Option<f32>,
}

impl TransferFunction {
    /// Opacity per mm at `hu`.
    #[inline(always)]
    pub fn opacity_at(&self, hu: f32) -> f32 {
        lerp_at(&self.opacity, hu, |a, b, w| a + (b - a) * w)
    }

    /// Linear RGB at `hu`.
    #[inline(always)]
    pub fn color_at(&self, hu: f32) -> [f32; 3] {
        lerp_at(&self.color, hu, |a, b, w| {
            [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * w)
        })
    }

    /// The largest opacity anywhere in [lo, hi] HU (the control points inside, and the ends):
    /// zero means a region whose values all lie in [lo, hi] is invisible and can be skipped.
    pub fn max_opacity_in(&self, lo: f32, hi: f32) -> f32 {
        self.opacity
            .iter()
            .filter(|p| p.0 >= lo && p.0 <= hi)
            .map(|p| p.1)
            .chain([self.opacity_at(lo), self.opacity_at(hi)])
            .fold(0.0, f32::max)
    }

    /// Checks the control points: at least one of each, finite, HU non-decreasing, values in
    /// [0, 1].
    pub fn validate(&self) -> Result<(), String> {
        if self.opacity.is_empty() || self.color.is_empty() {
            return Err("needs at least one opacity and one color point".into());
        }
        let ok =
            |hu: &[f32]| hu.iter().all(|h| h.is_finite()) && hu.windows(2).all(|w| w[0] <= w[1]);
        let o: Vec<f32> = self.opacity.iter().map(|p| p.0).collect();
        let c: Vec<f32> = self.color.iter().map(|p| p.0).collect();
        if !ok(&o) || !ok(&c) {
            return Err("control point HU values must be finite and increasing".into());
        }
        let unit = |v: f32| (0.0..=1.0).contains(&v);
        if !self.opacity.iter().all(|p| unit(p.1))
            || !self.color.iter().all(|p| p.1.iter().all(|&v| unit(v)))
        {
            return Err("opacity and color values must lie in [0, 1]".into());
        }
        Ok(())
    }

    /// Reads a TOML file:
    ///
    /// ```toml
    /// opacity = [[-1000, 0], [150, 0], [300, 0.6], [3000, 0.8]]   # HU, opacity per mm
    /// color = [[150, 0.9, 0.6, 0.4], [1000, 1, 1, 0.9]]           # HU, linear r g b
    /// ambient = 0.1        # optional shading terms
    /// diffuse = 0.9
    /// specular = 0.2
    /// specular_power = 10
    /// ```
    pub fn load(path: &Path) -> Result<TransferFunction, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        let f: TfFile = toml::from_str(&text)
            .map_err(|e| format!("{}: not a transfer function: {e}", path.display()))?;
        let d = Shading::default();
        let tf = TransferFunction {
            opacity: f.opacity.iter().map(|p| (p[0], p[1])).collect(),
            color: f.color.iter().map(|p| (p[0], [p[1], p[2], p[3]])).collect(),
            shading: Shading {
                ambient: f.ambient.unwrap_or(d.ambient),
                diffuse: f.diffuse.unwrap_or(d.diffuse),
                specular: f.specular.unwrap_or(d.specular),
                power: f.specular_power.unwrap_or(d.power),
            },
        };
        tf.validate()
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(tf)
    }
}
