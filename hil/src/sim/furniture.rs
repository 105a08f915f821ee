//! Furniture: the scenario's `[[furniture]]` items, each a kind of object (a chair, a rack, a
//! coat stand) expanded into boxes, cylinders and capsules of realistic proportions.
//!
//! An item stands on `base_z_m` with its footprint centred on `at`, turned by `yaw_deg`; its
//! length runs along its own x, so `size_m` = [length, width, height] is its bounding box. The
//! parts of each kind are in [`parts`]; every part lies inside that box.

mod parts;

use crate::rng::hash2;
use crate::sim::shapes::{Capsule, Cylinder, Solid, YawBox, V3};
use parts::{Mat, Shape};
use serde::Deserialize;

/// Sizes above this are refused: no piece of furniture is longer, and a seat row's seat count
/// follows its length.
pub const MAX_SIZE_M: f64 = 100.0;

/// The kinds of furniture; the scenario file names them in snake_case.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FurnitureKind {
    Chair,
    Table,
    RoundTable,
    Desk,
    Sofa,
    Bed,
    Shelving,
    Rack,
    Pillar,
    Pole,
    Plant,
    CoatStand,
    FloorLamp,
    Bin,
    Radiator,
    Bench,
    Pallet,
    PalletStack,
    Mannequin,
    CubicleWall,
    KitchenIsland,
    SeatRow,
    Cabinet,
    Box,
}

/// Each kind's file name, default size (length, width, height) and default material.
const TABLE: [(FurnitureKind, &str, [f64; 3], &str); 24] = {
    use FurnitureKind as K;
    [
        (K::Chair, "chair", [0.45, 0.45, 0.9], "wood"),
        (K::Table, "table", [1.4, 0.8, 0.75], "wood"),
        (K::RoundTable, "round_table", [0.9, 0.9, 0.75], "wood"),
        (K::Desk, "desk", [1.4, 0.7, 0.75], "wood"),
        (K::Sofa, "sofa", [2.0, 0.9, 0.85], "fabric"),
        (K::Bed, "bed", [2.0, 1.4, 1.0], "wood"),
        (K::Shelving, "shelving", [1.0, 0.4, 1.9], "wood"),
        (K::Rack, "rack", [2.7, 1.1, 4.5], "metal"),
        (K::Pillar, "pillar", [0.4, 0.4, 3.0], "concrete"),
        (K::Pole, "pole", [0.06, 0.06, 2.5], "metal"),
        (K::Plant, "plant", [0.5, 0.5, 1.2], "plastic"),
        (K::CoatStand, "coat_stand", [0.5, 0.5, 1.8], "wood"),
        (K::FloorLamp, "floor_lamp", [0.3, 0.3, 1.7], "metal"),
        (K::Bin, "bin", [0.35, 0.35, 0.6], "plastic"),
        (K::Radiator, "radiator", [1.0, 0.1, 0.6], "metal"),
        (K::Bench, "bench", [1.5, 0.4, 0.45], "wood"),
        (K::Pallet, "pallet", [1.2, 0.8, 0.15], "wood"),
        (K::PalletStack, "pallet_stack", [1.2, 0.8, 1.2], "wood"),
        (K::Mannequin, "mannequin", [0.5, 0.35, 1.8], "plastic"),
        (K::CubicleWall, "cubicle_wall", [1.8, 0.06, 1.4], "fabric"),
        (K::KitchenIsland, "kitchen_island", [1.8, 0.9, 0.9], "wood"),
        (K::SeatRow, "seat_row", [4.0, 0.6, 0.9], "fabric"),
        (K::Cabinet, "cabinet", [1.0, 0.5, 1.1], "wood"),
        (K::Box, "box", [0.6, 0.4, 0.4], "cardboard"),
    ]
};

impl FurnitureKind {
    pub const ALL: [FurnitureKind; 24] = {
        let mut all = [FurnitureKind::Box; 24];
        let mut i = 0;
        while i < TABLE.len() {
            all[i] = TABLE[i].0;
            i += 1;
        }
        all
    };

    fn row(self) -> (FurnitureKind, &'static str, [f64; 3], &'static str) {
        TABLE.iter().copied().find(|r| r.0 == self).unwrap_or((self, "box", [0.6, 0.4, 0.4], "cardboard"))
    }

    /// The name in scenario files.
    pub fn name(self) -> &'static str {
        self.row().1
    }

    /// Overall length, width and height when the item gives no `size_m`.
    pub fn default_size_m(self) -> [f64; 3] {
        self.row().2
    }

    /// The material of the item's main parts when it names none.
    pub fn default_material(self) -> &'static str {
        self.row().3
    }
}

impl std::fmt::Display for FurnitureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One `[[furniture]]` item of a scenario.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Furniture {
    pub kind: FurnitureKind,
    /// Centre of the footprint.
    pub at: [f64; 2],
    #[serde(default)]
    pub yaw_deg: f64,
    /// Height of the floor it stands on (a platform, a stage).
    #[serde(default)]
    pub base_z_m: f64,
    /// Overall length (along its own x), width and height; the kind's default when absent.
    pub size_m: Option<[f64; 3]>,
    /// Material of the main parts (accents such as a mattress or leaves keep theirs).
    pub material: Option<String>,
    #[serde(default)]
    pub name: String,
}

impl Furniture {
    /// An item of `kind` at `at`, with every default.
    pub fn new(kind: FurnitureKind, at: [f64; 2]) -> Self {
        Self { kind, at, yaw_deg: 0.0, base_z_m: 0.0, size_m: None, material: None, name: String::new() }
    }

    pub fn size_m(&self) -> [f64; 3] {
        self.size_m.unwrap_or(self.kind.default_size_m())
    }

    pub fn material(&self) -> &str {
        self.material.as_deref().unwrap_or(self.kind.default_material())
    }

    pub fn yaw_rad(&self) -> f64 {
        self.yaw_deg.to_radians()
    }

    /// Its name, or its kind when it has none (for messages).
    pub fn label(&self) -> String {
        if self.name.is_empty() {
            self.kind.name().to_string()
        } else {
            self.name.clone()
        }
    }

    /// The footprint as an obstacle: centre (m), half length and half width (m), and yaw (rad).
    pub fn footprint(&self) -> ([f64; 2], [f64; 2], f64) {
        let [l, w, _] = self.size_m();
        (self.at, [l / 2.0, w / 2.0], self.yaw_rad())
    }

    /// What is wrong with the item's numbers, if anything (its material is the scenario's to
    /// check, against its own materials).
    pub fn check(&self) -> Result<(), String> {
        let finite = self.at.iter().chain([&self.yaw_deg, &self.base_z_m]).all(|v| v.is_finite());
        if !finite {
            return Err(format!("{}: at, yaw_deg and base_z_m must be finite", self.label()));
        }
        for (what, v) in ["length", "width", "height"].iter().zip(self.size_m()) {
            if !(v.is_finite() && v > 0.0 && v <= MAX_SIZE_M) {
                return Err(format!("{}: size_m {what} must be in (0, {MAX_SIZE_M}] m, not {v}", self.label()));
            }
        }
        Ok(())
    }

    /// What varies inside a kind (boxes on shelves, rack loads) follows from where it stands, so
    /// it is the same in every run and differs from one rack to the next.
    fn seed(&self) -> u64 {
        hash2(self.at[0].to_bits(), self.at[1].to_bits())
    }

    /// Every material its parts take: its own, then the fixed ones of its accents.
    pub fn materials(&self) -> Vec<&str> {
        let mut out = vec![self.material()];
        for part in parts::parts(self.kind, self.size_m(), self.seed()) {
            if let Mat::Named(m) = part.mat {
                if !out.contains(&m) {
                    out.push(m);
                }
            }
        }
        out
    }

    /// The item as solids in the world; `albedo_of` gives a material's albedo.
    pub fn solids(&self, albedo_of: impl Fn(&str) -> f32) -> Vec<Solid> {
        let main = albedo_of(self.material());
        let (yaw, (sin, cos)) = (self.yaw_rad(), self.yaw_rad().sin_cos());
        let place = |p: V3| {
            V3::new(self.at[0] + cos * p.x - sin * p.y, self.at[1] + sin * p.x + cos * p.y, self.base_z_m + p.z)
        };
        let solid = |part: parts::Part| {
            let albedo = match part.mat {
                Mat::Main => main,
                Mat::Named(m) => albedo_of(m),
            };
            match part.shape {
                Shape::Box { min, max } => YawBox::new(place((min + max) / 2.0), max - min, yaw, albedo).into(),
                Shape::Cylinder { x, y, r, z0, z1 } => {
                    let c = place(V3::new(x, y, 0.0));
                    let z = self.base_z_m;
                    Cylinder { x_m: c.x, y_m: c.y, z0_m: z + z0, z1_m: z + z1, radius_m: r, albedo }.into()
                }
                Shape::Capsule { a, b, r } => Capsule { a: place(a), b: place(b), radius: r, albedo }.into(),
            }
        };
        parts::parts(self.kind, self.size_m(), self.seed()).into_iter().map(solid).collect()
    }
}

#[cfg(test)]
mod tests;
