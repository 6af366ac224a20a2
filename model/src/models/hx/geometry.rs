//! Geometry of the microtube evaporator on the test bench.
//!
//! An automotive-size brazed aluminium evaporator: flat multiport (microchannel) tubes
//! stacked with louvered fins between them, air crossing the tubes in a single slab.
//! The refrigerant runs through `passes` passes in series; each pass is a bank of
//! `tubes_per_pass` tubes in parallel, each tube with `ports` square channels. The
//! model unrolls the serpentine into one equivalent flow path of length
//! `passes × tube_length` through `tubes_per_pass × ports` parallel channels, and gives each
//! segment of that path the share of the face (air flow, fin area, wall mass) its length
//! fraction covers.
//!
//! | quantity | value |
//! |---|---|
//! | face (tube length × stack height) | 0.30 m × 0.24 m |
//! | tubes, passes | 24 tubes, 4 passes of 6 tubes |
//! | tube: depth × thickness, wall | 40 mm × 2.0 mm |
//! | ports per tube, port size | 20 square ports, 1.1 mm × 1.1 mm (D_h = 1.1 mm) |
//! | refrigerant path length, flow area | 1.2 m, 145 mm² (G ≈ 145 kg/(m² s) at 0.021 kg/s) |
//! | fins: pitch, thickness, height (gap) | 1.3 mm, 0.10 mm, 8.0 mm |
//! | louvers: pitch, length, angle | 1.1 mm, 6.8 mm, 27° |
//! | aluminium (3003): density, heat capacity, fin conductivity | 2730 kg/m³, 893 J/(kg K), 190 W/(m K) |
//!
//! Derived (see the unit test): refrigerant-side wetted area 0.634 m², air-side area
//! 4.22 m² (fins 87 %), face 0.075 m² (1.7 m/s at 0.15 kg/s), minimum free-flow area
//! 0.0554 m², wall heat capacity 1.43 kJ/K.

/// Dimensions of the core (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Length of one tube = width of the face (m).
    pub tube_length: f64,
    /// Number of tubes in the stack.
    pub tubes: usize,
    /// Refrigerant passes in series.
    pub passes: usize,
    /// Tube depth in the air-flow direction (m); fins have the same depth.
    pub tube_depth: f64,
    /// Outer tube thickness across the stack (m).
    pub tube_thickness: f64,
    /// Channels per tube.
    pub ports: usize,
    /// Square channel side (m).
    pub port_side: f64,
    /// Fin pitch along the tube (m).
    pub fin_pitch: f64,
    pub fin_thickness: f64,
    /// Fin height = gap between neighbouring tubes (m).
    pub fin_height: f64,
    pub louver_pitch: f64,
    pub louver_length: f64,
    /// Louver angle (degrees).
    pub louver_angle: f64,
    pub wall_density: f64,
    pub wall_specific_heat: f64,
    pub fin_conductivity: f64,
}

impl Geometry {
    /// The bench's evaporator.
    pub const BENCH: Geometry = Geometry {
        tube_length: 0.30,
        tubes: 24,
        passes: 4,
        tube_depth: 0.040,
        tube_thickness: 0.0020,
        ports: 20,
        port_side: 0.0011,
        fin_pitch: 0.0013,
        fin_thickness: 0.0001,
        fin_height: 0.0080,
        louver_pitch: 0.0011,
        louver_length: 0.0068,
        louver_angle: 27.0,
        wall_density: 2730.0,
        wall_specific_heat: 893.0,
        fin_conductivity: 190.0,
    };

    pub fn tubes_per_pass(&self) -> f64 {
        (self.tubes / self.passes) as f64
    }

    /// Length of the unrolled refrigerant path (m).
    pub fn path_length(&self) -> f64 {
        self.passes as f64 * self.tube_length
    }

    /// Parallel channels of the path.
    pub fn channels(&self) -> f64 {
        self.tubes_per_pass() * self.ports as f64
    }

    /// Refrigerant flow area (m²).
    pub fn flow_area(&self) -> f64 {
        self.channels() * self.port_side * self.port_side
    }

    /// Channel hydraulic diameter (m).
    pub fn hydraulic_diameter(&self) -> f64 {
        self.port_side
    }

    /// Refrigerant-side wetted area of the whole path (m²).
    pub fn refrigerant_area(&self) -> f64 {
        self.channels() * 4.0 * self.port_side * self.path_length()
    }

    /// Number of fins along one tube row.
    pub fn fins_per_row(&self) -> f64 {
        self.tube_length / self.fin_pitch
    }

    /// Fin rows: one between each pair of tubes and one at each end plate.
    pub fn fin_rows(&self) -> f64 {
        (self.tubes + 1) as f64
    }

    /// Face area (m²).
    pub fn face_area(&self) -> f64 {
        self.tube_length * self.fin_rows() * (self.fin_height + self.tube_thickness)
    }

    /// Fin surface, both sides (m²).
    pub fn fin_area(&self) -> f64 {
        2.0 * self.fin_rows() * self.fins_per_row() * self.fin_height * self.tube_depth
    }

    /// Air-side area of the tubes between the fins (m²).
    pub fn tube_outer_area(&self) -> f64 {
        let covered = self.fin_thickness / self.fin_pitch;
        2.0 * self.tubes as f64 * self.tube_length * self.tube_depth * (1.0 - covered)
    }

    /// Total air-side area (m²).
    pub fn air_area(&self) -> f64 {
        self.fin_area() + self.tube_outer_area()
    }

    /// Minimum free-flow area on the air side (m²).
    pub fn air_min_flow_area(&self) -> f64 {
        let open_per_gap = self.fin_height * (1.0 - self.fin_thickness / self.fin_pitch);
        self.fin_rows() * self.tube_length * open_per_gap
    }

    /// Heat capacity of tubes and fins (J/K).
    pub fn wall_heat_capacity(&self) -> f64 {
        let tube_solid = self.tube_depth * self.tube_thickness
            - self.ports as f64 * self.port_side * self.port_side;
        let tubes = self.tubes as f64 * self.tube_length * tube_solid;
        let fins = 0.5 * self.fin_area() * self.fin_thickness;
        (tubes + fins) * self.wall_density * self.wall_specific_heat
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_dimensions_are_as_documented() {
        let g = Geometry::BENCH;
        assert!((g.path_length() - 1.2).abs() < 1e-12);
        assert!((g.flow_area() - 145.2e-6).abs() < 1e-12);
        let a_ref = g.refrigerant_area();
        let a_air = g.air_area();
        let c = g.wall_heat_capacity();
        assert!((a_ref - 0.634).abs() < 0.001, "{a_ref}");
        assert!((a_air - 4.22).abs() < 0.01, "{a_air}");
        assert!((g.fin_area() / a_air - 0.874).abs() < 0.001);
        assert!(
            (g.air_min_flow_area() - 0.0554).abs() < 0.0001,
            "{}",
            g.air_min_flow_area()
        );
        assert!((c - 1430.0).abs() < 1.0, "{c}");
    }
}
