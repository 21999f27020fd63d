//! The units a reading line can be written in.

/// A unit of mass for the reading lines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Unit {
    /// Grams.
    G,
    /// Kilograms.
    Kg,
    /// Avoirdupois pounds (453.592 37 g, exact by definition).
    Lb,
    /// Avoirdupois ounces (28.349 523 125 g, exact by definition).
    Oz,
}

impl Unit {
    /// Every unit, in the order `help` lists them.
    pub const ALL: [Unit; 4] = [Unit::G, Unit::Kg, Unit::Lb, Unit::Oz];

    /// Grams in one of this unit.
    pub fn grams(self) -> f32 {
        match self {
            Unit::G => 1.0,
            Unit::Kg => 1000.0,
            Unit::Lb => 453.592_37,
            Unit::Oz => 28.349_524,
        }
    }

    /// `grams` in this unit.
    pub fn from_grams(self, grams: f32) -> f32 {
        grams / self.grams()
    }

    /// The name on the console (`g`, `kg`, `lb`, `oz`).
    pub fn name(self) -> &'static str {
        match self {
            Unit::G => "g",
            Unit::Kg => "kg",
            Unit::Lb => "lb",
            Unit::Oz => "oz",
        }
    }

    /// The unit a console word names (any case).
    pub fn from_name(word: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|unit| unit.name().eq_ignore_ascii_case(word))
    }

    /// Decimals that show a step of `resolution_g` grams in this unit (the first decimal
    /// where the step is at least one digit; 3 for a step that is not a positive number, at
    /// most 7).
    pub fn decimals(self, resolution_g: f32) -> usize {
        let step = self.from_grams(resolution_g);
        if !(step.is_finite() && step > 0.0) {
            return 3;
        }
        let mut decimals = 0;
        let mut scale = 1.0f32;
        while step * scale < 1.0 && decimals < 7 {
            scale *= 10.0;
            decimals += 1;
        }
        decimals
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_and_names_round_trip() {
        assert!((Unit::Kg.from_grams(138.32) - 0.13832).abs() < 1e-7);
        assert!((Unit::Lb.from_grams(453.59237) - 1.0).abs() < 1e-7);
        assert!((Unit::Oz.from_grams(28.349_524) - 1.0).abs() < 1e-7);
        for unit in Unit::ALL {
            assert_eq!(Unit::from_name(unit.name()), Some(unit));
            assert_eq!(Unit::from_name(&unit.name().to_uppercase()), Some(unit));
        }
        assert_eq!(Unit::from_name("stone"), None);
    }

    #[test]
    fn decimals_resolve_the_scale_interval() {
        // e = 0.1 g: 1 decimal in g, 4 in kg (0.0001 kg), 4 in lb (0.00022 lb), 3 in oz
        // (0.0035 oz).
        assert_eq!(Unit::G.decimals(0.1), 1);
        assert_eq!(Unit::Kg.decimals(0.1), 4);
        assert_eq!(Unit::Lb.decimals(0.1), 4);
        assert_eq!(Unit::Oz.decimals(0.1), 3);
        assert_eq!(Unit::G.decimals(f32::NAN), 3);
    }
}
