//! Wavefront MTL material libraries (`mtllib` in an OBJ file) -> our materials.
//!
//! The mapping (docs/SCENE_FORMAT.md, "OBJ materials"): `Kd` -> kd, `Ks` -> ks, `Ns` -> the
//! max-Phong exponent n, `Ke` -> the emitted radiance of the faces that use the material. A
//! material without `Ks` (or with a black one) is diffuse. MTL files are written for
//! renderers that do not conserve energy, so a Ks that would make the max-Phong reflect more
//! than it receives is scaled down until the largest directional albedo is 1, and a note
//! says so; a Kd above 1 is refused (nothing can be scaled there without changing the colour
//! the file asks for).

use super::brdf::max_directional_albedo;
use super::{MaterialKind, Rgb};

/// One `newmtl` block.
#[derive(Debug, Clone, PartialEq)]
pub struct MtlMaterial {
    pub name: String,
    /// The line of its `newmtl`.
    pub line: usize,
    pub kind: MaterialKind,
    /// `Ke`: emitted radiance (black when absent).
    pub emission: Rgb,
    /// What the file asks for that is not rendered, or was changed: one line each.
    pub notes: Vec<String>,
}

/// An error at a line of the MTL file.
#[derive(Debug, Clone, PartialEq)]
pub struct MtlError {
    pub line: usize,
    pub message: String,
}

/// Statements that are read for nothing, by design: ambient colour and the illumination
/// model are about other renderers' shading, Ni about refraction, which we do not render.
const IGNORED_QUIETLY: &[&str] = &["Ka", "illum", "Ni", "Pr", "Pm", "Ps", "Pc", "Pcr", "aniso", "anisor"];

/// The material properties we do not render, reported with a note when set.
const NOT_RENDERED: &[(&str, &str)] = &[
    ("d", "transparency (d)"),
    ("Tr", "transparency (Tr)"),
    ("Tf", "transmission filter (Tf)"),
    ("map_Ka", "texture map_Ka"),
    ("map_Kd", "texture map_Kd (the constant Kd is used)"),
    ("map_Ks", "texture map_Ks (the constant Ks is used)"),
    ("map_Ke", "texture map_Ke (the constant Ke is used)"),
    ("map_Ns", "texture map_Ns"),
    ("map_d", "texture map_d"),
    ("map_Bump", "bump map"),
    ("map_bump", "bump map"),
    ("bump", "bump map"),
    ("disp", "displacement map"),
    ("decal", "decal map"),
    ("refl", "reflection map"),
    ("norm", "normal map"),
];

/// Reads every `newmtl` block of an MTL file. Errors name the line.
pub fn parse_mtl(text: &str) -> Result<Vec<MtlMaterial>, MtlError> {
    struct Open {
        name: String,
        line: usize,
        kd: Rgb,
        ks: Rgb,
        ns: f32,
        ke: Rgb,
        notes: Vec<String>,
    }
    let mut done: Vec<MtlMaterial> = Vec::new();
    let mut open: Option<Open> = None;
    let finish = |m: Open, done: &mut Vec<MtlMaterial>| -> Result<(), MtlError> {
        let mut notes = m.notes;
        let kind = map_material(&m.name, m.kd, m.ks, m.ns, &mut notes)
            .map_err(|message| MtlError { line: m.line, message })?;
        done.push(MtlMaterial { name: m.name, line: m.line, kind, emission: m.ke, notes });
        Ok(())
    };
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let err = |message: String| MtlError { line, message };
        let content = raw.split('#').next().unwrap_or("").trim();
        let Some(keyword) = content.split_whitespace().next() else { continue };
        let rest = content[keyword.len()..].trim();
        if keyword == "newmtl" {
            if rest.is_empty() {
                return Err(err("expected a material name after `newmtl`".into()));
            }
            if done.iter().any(|m| m.name == rest) || open.as_ref().is_some_and(|m| m.name == rest) {
                return Err(err(format!("material \"{rest}\" is defined twice in this file")));
            }
            if let Some(m) = open.take() {
                finish(m, &mut done)?;
            }
            open = Some(Open {
                name: rest.into(),
                line,
                kd: [0.0; 3],
                ks: [0.0; 3],
                ns: 0.0,
                ke: [0.0; 3],
                notes: Vec::new(),
            });
            continue;
        }
        let Some(m) = open.as_mut() else {
            return Err(err(format!("`{keyword}` before the first `newmtl`")));
        };
        match keyword {
            "Kd" => m.kd = colour(keyword, rest).map_err(err)?,
            "Ks" => m.ks = colour(keyword, rest).map_err(err)?,
            "Ke" => m.ke = colour(keyword, rest).map_err(err)?,
            "Ns" => {
                let n = number(keyword, rest).map_err(err)?;
                if n < 0.0 {
                    return Err(err(format!("Ns must be >= 0, got {n}")));
                }
                m.ns = n as f32;
            }
            k if IGNORED_QUIETLY.contains(&k) => {}
            k => {
                let what = match NOT_RENDERED.iter().find(|(key, _)| *key == k) {
                    // Fully opaque is what we render anyway.
                    Some(("d", _)) if rest.parse::<f64>() == Ok(1.0) => continue,
                    Some(("Tr", _)) if rest.parse::<f64>() == Ok(0.0) => continue,
                    Some((_, what)) => what.to_string(),
                    None => format!("the statement `{k}`"),
                };
                m.notes.push(format!("line {line}: {what} is not rendered"));
            }
        }
    }
    if let Some(m) = open.take() {
        finish(m, &mut done)?;
    }
    Ok(done)
}

/// Kd, Ks, Ns -> diffuse or max-Phong, Ks scaled down (with a note) to conserve energy.
pub fn map_material(name: &str, kd: Rgb, ks: Rgb, ns: f32, notes: &mut Vec<String>) -> Result<MaterialKind, String> {
    if let Some(c) = kd.iter().position(|&x| x > 1.0) {
        return Err(format!(
            "material \"{name}\": Kd must be <= 1 in every channel (a diffuse albedo above 1 creates energy), got {} in channel {}",
            kd[c],
            ["red", "green", "blue"][c]
        ));
    }
    if ks.iter().all(|&x| x == 0.0) {
        return Ok(MaterialKind::Diffuse { albedo: kd });
    }
    let (specular, scale) = fit_specular(kd, ks, ns);
    if scale < 1.0 {
        notes.push(format!(
            "material \"{name}\": Ks scaled by {scale:.4} to [{:.4}, {:.4}, {:.4}] so that it reflects no more light than it receives (Kd + Ks with Ns {ns} exceeded albedo 1)",
            specular[0], specular[1], specular[2]
        ));
    }
    Ok(MaterialKind::Phong { diffuse: kd, specular, shininess: ns })
}

/// The ks (and the factor it was scaled by, 1 if none) that keeps max-Phong (kd, ks, n)
/// within albedo 1 in every channel, kd <= 1 given: the largest directional albedo is
/// kd + ks L(n), L the largest albedo of the lobe, so ks is scaled by the smallest
/// (1 - kd) / (ks L) over the channels, then nudged down past the f32 roundings.
pub fn fit_specular(kd: Rgb, ks: Rgb, n: f32) -> (Rgb, f32) {
    let fits = |ks: Rgb| {
        max_directional_albedo(&MaterialKind::Phong { diffuse: kd, specular: ks, shininess: n })
            .iter()
            .all(|&a| a <= 1.0)
    };
    if fits(ks) {
        return (ks, 1.0);
    }
    let lobe = f64::from(
        max_directional_albedo(&MaterialKind::Phong { diffuse: [0.0; 3], specular: [1.0; 3], shininess: n })[0],
    );
    let mut scale = (0..3)
        .filter(|&c| ks[c] > 0.0)
        .map(|c| (1.0 - f64::from(kd[c])) / (f64::from(ks[c]) * lobe))
        .fold(1.0f64, f64::min) as f32;
    let mut scaled = ks.map(|x| x * scale);
    while !fits(scaled) {
        scale *= 1.0 - 1e-6;
        scaled = ks.map(|x| x * scale);
    }
    (scaled, scale)
}

fn number(keyword: &str, token: &str) -> Result<f64, String> {
    let x: f64 = token.parse().map_err(|_| format!("expected a number after `{keyword}`, got `{token}`"))?;
    if !x.is_finite() || x.abs() > f64::from(f32::MAX) {
        return Err(format!("expected a finite number after `{keyword}`, got `{token}`"));
    }
    Ok(x)
}

/// `K? r g b` (one number stands for all three); `spectral` and `xyz` forms are refused.
fn colour(keyword: &str, rest: &str) -> Result<Rgb, String> {
    let tokens: Vec<&str> = rest.split_whitespace().collect();
    if matches!(tokens.first(), Some(&"spectral") | Some(&"xyz")) {
        return Err(format!("`{keyword} {}` colours are not supported: give r g b", tokens[0]));
    }
    let values = match tokens.len() {
        1 => vec![number(keyword, tokens[0])?; 3],
        3 => tokens.iter().map(|t| number(keyword, t)).collect::<Result<Vec<_>, _>>()?,
        n => return Err(format!("expected 3 numbers (r g b) after `{keyword}`, got {n}")),
    };
    if let Some(c) = values.iter().position(|&x| x < 0.0) {
        return Err(format!(
            "{keyword} must be >= 0 in every channel, got {} in channel {}",
            values[c],
            ["red", "green", "blue"][c]
        ));
    }
    Ok([values[0] as f32, values[1] as f32, values[2] as f32])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_blocks_and_maps_them() {
        let text = "\
# two materials
newmtl white
Ka 1 1 1
Kd 0.7 0.7 0.7
illum 2

newmtl glossy lamp
Kd 0.2 0.1 0.1
Ks 0.3 0.3 0.3
Ns 20
Ke 5 4 3
map_Kd wood.png
d 1.0
";
        let m = parse_mtl(text).unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(m[0].name, "white");
        assert_eq!(m[0].kind, MaterialKind::Diffuse { albedo: [0.7; 3] });
        assert!(m[0].notes.is_empty());
        assert_eq!(m[1].name, "glossy lamp");
        assert_eq!(m[1].line, 7);
        assert_eq!(m[1].kind, MaterialKind::Phong { diffuse: [0.2, 0.1, 0.1], specular: [0.3; 3], shininess: 20.0 });
        assert_eq!(m[1].emission, [5.0, 4.0, 3.0]);
        assert_eq!(m[1].notes.len(), 1, "{:?}", m[1].notes);
        assert!(m[1].notes[0].contains("line 12") && m[1].notes[0].contains("map_Kd"));
    }

    #[test]
    fn a_specular_that_gains_energy_is_scaled_to_fit() {
        // Kd 0.8 with Ks 1, Ns 10 reflects 0.8 + 2 pi / 12 = 1.32 at normal incidence.
        let mut notes = Vec::new();
        let kind = map_material("shiny", [0.8; 3], [1.0; 3], 10.0, &mut notes).unwrap();
        let albedo = max_directional_albedo(&kind);
        assert!(albedo.iter().all(|&a| a <= 1.0), "{albedo:?}");
        // Scaled to fit, not further: the largest albedo is 1 to within the nudges.
        assert!(albedo.iter().all(|&a| a > 0.9999), "{albedo:?}");
        assert_eq!(notes.len(), 1);
        assert!(notes[0].contains("Ks scaled by"), "{notes:?}");
        // One that fits is kept as written, with no note.
        let mut quiet = Vec::new();
        let kept = map_material("soft", [0.5; 3], [0.05; 3], 10.0, &mut quiet).unwrap();
        assert_eq!(kept, MaterialKind::Phong { diffuse: [0.5; 3], specular: [0.05; 3], shininess: 10.0 });
        assert!(quiet.is_empty());
    }

    #[test]
    fn errors_name_their_line() {
        let cases = [
            ("Kd 1 1 1\n", 1, "before the first `newmtl`"),
            ("newmtl a\nKd 1 1\n", 2, "expected 3 numbers"),
            ("newmtl a\nKd 1 x 1\n", 2, "expected a number"),
            ("newmtl a\nKs -1 0 0\n", 2, ">= 0"),
            ("newmtl a\nNs -3\n", 2, "Ns must be >= 0"),
            ("newmtl a\n\nKd 1.5 0 0\n", 1, "Kd must be <= 1"),
            ("newmtl a\nnewmtl a\n", 2, "defined twice"),
            ("newmtl\n", 1, "material name"),
            ("newmtl a\nKd spectral x.spd\n", 2, "not supported"),
        ];
        for (text, line, message) in cases {
            let e = parse_mtl(text).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e:?}");
            assert!(e.message.contains(message), "{text:?}: {e:?}");
        }
    }
}
