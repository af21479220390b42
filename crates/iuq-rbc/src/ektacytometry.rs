//! The ektacytometry data the RBC model is calibrated on: LORRCA elongation indices of healthy
//! and 0.5 mM TBHP-treated red cells at 15 shear stresses (Gutierrez et al., Langmuir 34(6),
//! 2363–2372, 2018, as tabulated in the IUQ study's analysis notebooks). The CSV is compiled into
//! the crate; [`EktacytometryData::parse`] reads files of the same layout.

use crate::error::{RbcError, Result};

/// The bundled CSV (`stress_pa,el_healthy,el_healthy_err,el_tbhp,el_tbhp_err`, `#` comments).
pub const GUTIERREZ_2018_CSV: &str = include_str!("../data/ektacytometry_gutierrez2018.csv");

/// One row of the table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct EktacytometryPoint {
    /// Shear stress in Pa.
    pub stress_pa: f64,
    /// Mean EL of healthy cells.
    pub el_healthy: f64,
    /// Its measurement error (±).
    pub el_healthy_err: f64,
    /// Mean EL of TBHP-treated cells.
    pub el_tbhp: f64,
    /// Its measurement error (±).
    pub el_tbhp_err: f64,
}

/// The table, rows in file order.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EktacytometryData {
    /// The rows.
    pub points: Vec<EktacytometryPoint>,
}

impl EktacytometryData {
    /// The bundled Gutierrez et al. (2018) table.
    pub fn gutierrez_2018() -> Self {
        // The bundled file is checked by a test; a parse failure here is impossible.
        Self::parse(GUTIERREZ_2018_CSV).unwrap_or(Self { points: Vec::new() })
    }

    /// Parse CSV text with the header `stress_pa,el_healthy,el_healthy_err,el_tbhp,el_tbhp_err`
    /// (any order) and `#` comment lines.
    pub fn parse(text: &str) -> Result<Self> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let (_, header) = lines
            .next()
            .ok_or_else(|| RbcError::InvalidData("no header line".into()))?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let column = |name: &str| {
            names
                .iter()
                .position(|n| *n == name)
                .ok_or_else(|| RbcError::InvalidData(format!("no column `{name}`")))
        };
        let idx = [
            column("stress_pa")?,
            column("el_healthy")?,
            column("el_healthy_err")?,
            column("el_tbhp")?,
            column("el_tbhp_err")?,
        ];
        let mut points = Vec::new();
        for (line, text) in lines {
            let cells: Vec<&str> = text.split(',').map(str::trim).collect();
            let value = |i: usize| -> Result<f64> {
                cells
                    .get(i)
                    .and_then(|c| c.parse::<f64>().ok())
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        RbcError::InvalidData(format!(
                            "line {}: column {} is not a number",
                            line + 1,
                            i + 1
                        ))
                    })
            };
            points.push(EktacytometryPoint {
                stress_pa: value(idx[0])?,
                el_healthy: value(idx[1])?,
                el_healthy_err: value(idx[2])?,
                el_tbhp: value(idx[3])?,
                el_tbhp_err: value(idx[4])?,
            });
        }
        Ok(Self { points })
    }

    /// The stresses within `[lower, upper]` Pa.
    pub fn stresses_within(&self, lower: f64, upper: f64) -> Vec<f64> {
        self.points
            .iter()
            .map(|p| p.stress_pa)
            .filter(|s| *s >= lower && *s <= upper)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bundled_table_parses() {
        let d = EktacytometryData::parse(GUTIERREZ_2018_CSV).unwrap();
        assert_eq!(d.points.len(), 15);
        assert_eq!(d.points[0].stress_pa, 0.30);
        assert_eq!(d.points[14].el_tbhp, 0.605);
        assert_eq!(
            d.stresses_within(0.64, 9.04),
            vec![0.64, 0.93, 1.36, 1.99, 2.91, 4.24, 6.19, 9.04]
        );
        assert_eq!(EktacytometryData::gutierrez_2018(), d);
    }

    #[test]
    fn malformed_tables_are_rejected() {
        assert!(EktacytometryData::parse("").is_err());
        assert!(EktacytometryData::parse("stress_pa,el_healthy\n1,2\n").is_err());
        let bad = "stress_pa,el_healthy,el_healthy_err,el_tbhp,el_tbhp_err\n1,x,0,0,0\n";
        assert!(EktacytometryData::parse(bad).is_err());
    }
}
