//! The update of four consecutive full-level grains side by side in AVX lanes (issue #16): the
//! grain pass's common case on a plain step of a deforming sample; and that of four rigid
//! grains, the same arithmetic without the deformation (`advance_lanes::<RIGID>`).
//!
//! Each lane computes what the one-grain update (`advance_grain` in
//! [`grain_pass`](super::grain_pass)) computes for its grain, with the same operations in the
//! same order (products and sums as glam computes them), then the grain's next frame
//! (`Frame::of_grain`): the same bits, grain by grain. The constitutive laws and the frames'
//! affine maps are the one-grain code's own functions, written over [`Real`]; the stresses and
//! the symplectic Euler step are written here a second time, for these two levels only, because
//! the one-grain update written over `Real` cost rigid grains 30–40 instructions a grain-step
//! (the twenty-ninth session's measurement). The unit test
//! `a_block_gives_each_grain_the_one_grain_updates_bits` holds the two together. The lanes run
//! on `F64x4`, AVX registers whose operations stay vector instructions. A block's grains are
//! moved into field lanes and back by 4 × 4 transposes of their records ([`Grain`], the stress
//! records and the frames are `repr(C)`), a few instructions a field.
//!
//! Measured on the dense bench (2,025 grains, dβ = 1°, callgrind): the full level's step from
//! 2,666 to 2,454 instructions a grain-step. Lanes filled value by value cost more than they
//! saved (the twenty-ninth session's attempt), and the update over `Lanes` rather than `F64x4`
//! was 138 instructions a grain against 94: the compiler split its lanes into scalars and
//! rebuilt them with shuffles.

use super::grain_pass::UpdateConstants;
use super::{BlockAngles, Frame, GrainStress, Parameters};
use crate::geometry::GrainShape;
use crate::geometry::affine::AffineState;
use crate::grain::Grain;
use crate::grain::constitutive::{incompressible_strains, principal_stress, strain_energy_density};
use crate::lanes::{Lanes, Real};
use glam::DVec2;
use std::f64::consts::PI;

/// Grains in a block: one AVX register's lanes.
pub(super) const BLOCK_GRAINS: usize = 4;

type GrainLanes = Lanes<BLOCK_GRAINS>;

/// The contact sums of a block's grains, field by field (lane `l`: the block's grain `l`), as
/// the grain pass's `ContactLoad` holds them for one grain.
#[derive(Clone, Copy, Default)]
pub(super) struct BlockLoads {
    pub force: [GrainLanes; 2],
    pub torque: GrainLanes,
    /// `sum_c f_c (x) r_c` by columns: `moment[b][a]` holds `f_a r_b`.
    pub moment: [[GrainLanes; 2]; 2],
    pub lost_area: GrainLanes,
}

/// What the update reads besides the grains and their loads, the same for every block of a
/// pass: the parameters, the grain pass's constants derived from them, and the time step.
#[derive(Clone, Copy)]
pub(super) struct BlockConstants<'a> {
    pub params: &'a Parameters,
    pub update: &'a UpdateConstants,
    pub dt: f64,
}

/// What a block's update gives besides the grains' new states and stress records: each
/// grain's current area and elastic energy, and which grains the per-grain checks must look
/// at.
#[derive(Clone, Copy, Default)]
pub(super) struct BlockOutcome {
    pub area: GrainLanes,
    pub elastic_energy: GrainLanes,
    /// Bit `l`: grain `l` may have failed a check of SPEC §9 (a value that is not finite, an
    /// inverted strain, a speed past the wave speed); the caller runs the one-grain checks on
    /// it, which decide. Clear bits passed every check.
    pub suspect: u32,
    /// A rigid block only: it wrote its four grains' frames, circles all (each grain's strains
    /// equal), as [`Frame::write_circle`] writes them.
    pub circle_frames: bool,
}

/// Whether this processor runs blocks (else the grain pass takes every grain one by one).
pub(super) fn blocks_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Advances the four full-level grains `grains` over a plain step: stresses, the symplectic
/// Euler step and the incompressibility correction (SPEC §3–§6), each lane with the bits of the
/// one-grain update; writes their stress records to `stresses`, with the loads' lost areas
/// and `contacts` (each grain's pair and wall contacts), and their frames for the next step
/// to `frames` ([`Frame::of_grain`], bit for bit: a grain's frame of the step's start is read
/// by its own contacts only, which are behind it). `e1`: the grains' principal directions,
/// replaced by those of the updated grains ([`Frame::of_grain_and_direction`]'s).
/// Only where [`blocks_available`] says so.
#[inline(always)]
pub(super) fn advance_full_block(
    grains: &mut [Grain],
    stresses: &mut [GrainStress],
    frames: &mut [Frame],
    loads: &BlockLoads,
    contacts: &[[u32; 2]; BLOCK_GRAINS],
    e1: &mut [DVec2],
    constants: &BlockConstants<'_>,
) -> BlockOutcome {
    assert!(
        grains.len() == BLOCK_GRAINS
            && stresses.len() == BLOCK_GRAINS
            && frames.len() == BLOCK_GRAINS
            && e1.len() == BLOCK_GRAINS
    );
    #[cfg(target_arch = "x86_64")]
    {
        assert!(blocks_available());
        // SAFETY: the processor has AVX (asserted just above), and the slices hold four
        // records each.
        unsafe {
            avx::advance_block::<false>(grains, stresses, frames, loads, contacts, e1, constants)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("blocks run on x86-64 only")
}

/// Advances the four rigid-level grains `grains` over a plain step as
/// [`advance_full_block`] does full-level ones: the stresses and the rigid-body motion of the
/// one-grain update at the rigid level, bit for bit, and their stress records. Where the four
/// are circles (each grain's strains equal: [`Frame::is_circle`]) it writes their frames'
/// first lines from the lanes, as [`Frame::write_circle`] does (and says so in
/// [`BlockOutcome::circle_frames`]); other frames are left to the caller. Only where
/// [`blocks_available`] says so.
#[inline(always)]
pub(super) fn advance_rigid_block(
    grains: &mut [Grain],
    stresses: &mut [GrainStress],
    frames: &mut [Frame],
    loads: &BlockLoads,
    contacts: &[[u32; 2]; BLOCK_GRAINS],
    constants: &BlockConstants<'_>,
) -> BlockOutcome {
    assert!(
        grains.len() == BLOCK_GRAINS
            && stresses.len() == BLOCK_GRAINS
            && frames.len() == BLOCK_GRAINS
    );
    #[cfg(target_arch = "x86_64")]
    {
        assert!(blocks_available());
        // SAFETY: the processor has AVX (asserted just above), and the slices hold four
        // records each; a rigid block reads no direction.
        unsafe {
            avx::advance_block::<true>(
                grains,
                stresses,
                frames,
                loads,
                contacts,
                &mut [],
                constants,
            )
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("blocks run on x86-64 only")
}

/// A grain's degrees of freedom in lanes, [`Grain`]'s fields by name.
#[derive(Clone, Copy)]
struct DofLanes<T> {
    radius: T,
    center: [T; 2],
    velocity: [T; 2],
    theta: T,
    omega: T,
    eps1: T,
    eps1_rate: T,
    eps2: T,
    eps2_rate: T,
    alpha: T,
    alpha_rate: T,
}

/// [`BlockLoads`] in registers.
#[derive(Clone, Copy)]
struct LoadLanes<T> {
    force: [T; 2],
    torque: T,
    moment: [[T; 2]; 2],
    lost_area: T,
}

/// What [`advance_lanes`] gives besides the new degrees of freedom ([`BlockOutcome`]'s
/// lanes).
#[derive(Clone, Copy)]
struct OutcomeLanes<T> {
    external: [T; 3],
    principal: [T; 2],
    area: T,
    elastic_energy: T,
    /// `Grain::mass`, for the frames.
    mass: T,
}

/// The update's arithmetic, lane by lane as the one-grain update (`advance_grain`) at the full
/// level, or at the rigid level where `RIGID` (the stresses and the rigid-body motion only,
/// `e1` unread): the order of every operation is that function's (and glam's inside it).
#[inline(always)]
fn advance_lanes<T: Real, const RIGID: bool>(
    dofs: &mut DofLanes<T>,
    load: &LoadLanes<T>,
    e1: [T; 2],
    constants: &BlockConstants<'_>,
) -> OutcomeLanes<T> {
    let (params, update) = (constants.params, constants.update);
    let splat = T::splat;
    let (one, half) = (splat(1.0), splat(0.5));
    let dt = splat(constants.dt);
    let density = splat(params.material.density);
    let radius = dofs.radius;
    // `Grain::reference_area`: PI R R.
    let reference_area = splat(PI) * radius * radius;
    let lost_fraction = load.lost_area / reference_area;
    // `Grain::ellipse_area` less the lost caps.
    let area = reference_area * (one + dofs.eps1) * (one + dofs.eps2) - load.lost_area;

    // Love–Weber stress: 0.5 (M + M^T) times 1 / area, and its principal-frame components.
    let [[m11, m21], [m12, m22]] = load.moment;
    let inv_area = one / area.max(splat(f64::MIN_POSITIVE));
    let xx = half * (m11 + m11) * inv_area;
    let yy = half * (m22 + m22) * inv_area;
    let xy = half * (m21 + m12) * inv_area;
    let moduli = &update.moduli;
    let (sigma1, sigma2) = principal_stress(moduli, dofs.eps1, dofs.eps2, lost_fraction);
    let elastic_energy =
        reference_area * strain_energy_density(moduli, dofs.eps1, dofs.eps2, lost_fraction);

    // Rigid-body motion; `Grain::mass` and `Grain::rotational_inertia_of_mass`.
    let mass = density * reference_area;
    let force_dt = dt / mass;
    for axis in 0..2 {
        dofs.velocity[axis] = dofs.velocity[axis] + load.force[axis] * force_dt;
    }
    if let Some(gravity) = update.gravity {
        for (axis, g) in gravity.to_array().into_iter().enumerate() {
            dofs.velocity[axis] = dofs.velocity[axis] + splat(g) * dt;
        }
    }
    let (a, b) = (one + dofs.eps1, one + dofs.eps2);
    let inertia = mass * radius * radius * (a * a + b * b) / splat(4.0);
    dofs.omega = dofs.omega + load.torque / inertia * dt;
    for axis in 0..2 {
        dofs.center[axis] = dofs.center[axis] + dofs.velocity[axis] * dt;
    }
    dofs.theta = dofs.theta + dofs.omega * dt;
    let outcome = OutcomeLanes {
        external: [xx, yy, xy],
        principal: [sigma1, sigma2],
        area,
        elastic_energy,
        mass,
    };
    if RIGID {
        return outcome;
    }

    // Deformation at the full level, driven by the stresses in the principal frame {e1, e2}.
    let e2 = [-e1[1], e1[0]];
    // glam's `DMat2 * DVec2` of the symmetric stress, and `DVec2::dot`.
    let apply = |v: [T; 2]| [xx * v[0] + xy * v[1], xy * v[0] + yy * v[1]];
    let dot = |a: [T; 2], b: [T; 2]| a[0] * b[0] + a[1] * b[1];
    let on_e2 = apply(e2);
    let (ext11, ext22, ext12) = (dot(e1, apply(e1)), dot(e2, on_e2), dot(e1, on_e2));
    let inv_modal_mass =
        splat(4.0) / (density * radius * radius * splat(params.deformation_mass_scale));
    let damping = splat(params.deformation_damping);
    let (s11, s22) = (ext11 - sigma1, ext22 - sigma2);
    dofs.eps1_rate = dofs.eps1_rate + (inv_modal_mass * s11 - damping * dofs.eps1_rate) * dt;
    dofs.eps2_rate = dofs.eps2_rate + (inv_modal_mass * s22 - damping * dofs.eps2_rate) * dt;
    let difference = dofs.eps1 - dofs.eps2;
    let alpha_force_acc = (splat(2.0) * difference * difference).if_greater(
        splat(params.k_alpha),
        inv_modal_mass * ext12 / (difference * splat(params.alpha_mass_scale)),
        splat(0.0),
    );
    dofs.alpha_rate = dofs.alpha_rate + (alpha_force_acc - damping * dofs.alpha_rate) * dt;
    dofs.eps1 = dofs.eps1 + dofs.eps1_rate * dt;
    dofs.eps2 = dofs.eps2 + dofs.eps2_rate * dt;
    dofs.alpha = dofs.alpha + dofs.alpha_rate * dt;
    if moduli.incompressible {
        let mean_before =
            half * (dofs.eps1 + dofs.eps2) - half * (dofs.eps1_rate + dofs.eps2_rate) * dt;
        let (eps1, eps2) = incompressible_strains(dofs.eps1, dofs.eps2, lost_fraction);
        let mean_rate = (half * (eps1 + eps2) - mean_before) / dt;
        let half_difference_rate = half * (dofs.eps1_rate - dofs.eps2_rate);
        dofs.eps1 = eps1;
        dofs.eps2 = eps2;
        dofs.eps1_rate = mean_rate + half_difference_rate;
        dofs.eps2_rate = mean_rate - half_difference_rate;
    }
    outcome
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_op_in_unsafe_fn)]
mod avx {
    // The helpers run AVX instructions: every one is inlined into `advance_block`, which
    // is compiled for AVX and called only where the processor has it.
    use super::*;
    use crate::lanes::avx::transpose;
    use std::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Neg, Sub};

    // The transposes read a grain as thirteen `f64`s, a stress record as seven words and a
    // frame as sixteen, without padding (`repr(C)`); which field each word is, the test
    // `records_are_the_words_the_transposes_move` checks.
    const _: () = {
        use std::mem::size_of;
        assert!(size_of::<Grain>() == 13 * 8);
        assert!(size_of::<GrainStress>() == 7 * 8);
        assert!(size_of::<Frame>() == 16 * 8);
        // A circle's first line as the rigid block writes it: centre, radius, mass; velocity,
        // spin, dilation rate.
        use std::mem::offset_of;
        assert!(offset_of!(Frame, center) == 0 && offset_of!(Frame, bounding_radius) == 16);
        assert!(offset_of!(Frame, mass) == 24 && offset_of!(Frame, velocity) == 32);
        assert!(offset_of!(Frame, omega) == 48 && offset_of!(Frame, circle_dilation) == 56);
    };

    /// Four `f64` lanes in an AVX register, with [`Real`]'s arithmetic: the operations of
    /// [`Lanes`] in vector instructions that stay vector instructions (written over `Lanes`,
    /// the compiler split the update's lanes into scalars and rebuilt them with shuffles).
    #[derive(Clone, Copy)]
    struct F64x4(__m256d);

    macro_rules! vector_operator {
        ($trait:ident, $method:ident, $intrinsic:ident) => {
            impl $trait for F64x4 {
                type Output = Self;
                #[inline(always)]
                fn $method(self, other: Self) -> Self {
                    // SAFETY: inlined into AVX code only (see the module's comment).
                    F64x4(unsafe { $intrinsic(self.0, other.0) })
                }
            }
        };
    }

    vector_operator!(Add, add, _mm256_add_pd);
    vector_operator!(Sub, sub, _mm256_sub_pd);
    vector_operator!(Mul, mul, _mm256_mul_pd);
    vector_operator!(Div, div, _mm256_div_pd);

    impl Neg for F64x4 {
        type Output = Self;
        #[inline(always)]
        fn neg(self) -> Self {
            // The sign bit flipped, as `-x` on one `f64`.
            // SAFETY: as above.
            F64x4(unsafe { _mm256_xor_pd(self.0, _mm256_set1_pd(-0.0)) })
        }
    }

    impl F64x4 {
        /// `self` where `other` is a NaN or `self` compares `KEEP` (greater, for a maximum)
        /// to it, else `other`: `Lanes`' `max` and `min`.
        #[inline(always)]
        fn unless_beaten<const KEEP: i32>(self, other: Self) -> Self {
            // SAFETY: as above.
            F64x4(unsafe {
                let take_self = _mm256_or_pd(
                    _mm256_cmp_pd::<_CMP_UNORD_Q>(other.0, other.0),
                    _mm256_cmp_pd::<KEEP>(self.0, other.0),
                );
                _mm256_blendv_pd(other.0, self.0, take_self)
            })
        }
    }

    impl Real for F64x4 {
        #[inline(always)]
        fn splat(value: f64) -> Self {
            // SAFETY: as above.
            F64x4(unsafe { _mm256_set1_pd(value) })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            // SAFETY: as above.
            F64x4(unsafe { _mm256_sqrt_pd(self.0) })
        }
        #[inline(always)]
        fn max(self, other: Self) -> Self {
            self.unless_beaten::<_CMP_GT_OQ>(other)
        }
        #[inline(always)]
        fn min(self, other: Self) -> Self {
            self.unless_beaten::<_CMP_LT_OQ>(other)
        }
        #[inline(always)]
        fn if_greater(self, than: Self, then: Self, otherwise: Self) -> Self {
            // SAFETY: as above.
            F64x4(unsafe {
                _mm256_blendv_pd(
                    otherwise.0,
                    then.0,
                    _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, than.0),
                )
            })
        }
    }

    #[inline(always)]
    unsafe fn load(lanes: &GrainLanes) -> F64x4 {
        F64x4(_mm256_load_pd(lanes.0.as_ptr()))
    }

    #[inline(always)]
    unsafe fn store(v: F64x4, lanes: &mut GrainLanes) {
        _mm256_store_pd(lanes.0.as_mut_ptr(), v.0)
    }

    /// See [`super::advance_full_block`]; where `RIGID`, [`super::advance_rigid_block`]
    /// (`e1` unread).
    ///
    /// # Safety
    /// The processor must have AVX, and `grains`, `stresses` and `frames` must hold four
    /// records each, `e1` too unless `RIGID`.
    #[target_feature(enable = "avx")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn advance_block<const RIGID: bool>(
        grains: &mut [Grain],
        stresses: &mut [GrainStress],
        frames: &mut [Frame],
        loads: &BlockLoads,
        contacts: &[[u32; 2]; BLOCK_GRAINS],
        e1: &mut [DVec2],
        constants: &BlockConstants<'_>,
    ) -> BlockOutcome {
        let base = grains.as_mut_ptr().cast::<f64>();
        // Grain `l`'s `f64`s 4q to 4q + 3 (the layout asserted above).
        let row = |l: usize, quarter: usize| _mm256_loadu_pd(base.add(13 * l + 4 * quarter));
        let quarter = |q: usize| transpose([row(0, q), row(1, q), row(2, q), row(3, q)]).map(F64x4);
        let [radius, center_x, center_y, velocity_x] = quarter(0);
        let [velocity_y, theta, omega, eps1] = quarter(1);
        let [eps1_rate, eps2, eps2_rate, alpha] = quarter(2);
        // The thirteenth `f64` of each record.
        let alpha_rate = F64x4(_mm256_set_pd(
            *base.add(13 * 3 + 12),
            *base.add(13 * 2 + 12),
            *base.add(13 + 12),
            *base.add(12),
        ));
        let mut dofs = DofLanes {
            radius,
            center: [center_x, center_y],
            velocity: [velocity_x, velocity_y],
            theta,
            omega,
            eps1,
            eps1_rate,
            eps2,
            eps2_rate,
            alpha,
            alpha_rate,
        };
        let e1_lanes = if RIGID {
            [F64x4::splat(0.0); 2]
        } else {
            // The directions `[c0, s0, c1, s1]`, `[c2, s2, c3, s3]` to cosines and sines.
            let directions = e1.as_ptr().cast::<f64>();
            let (first, second) = (
                _mm256_loadu_pd(directions),
                _mm256_loadu_pd(directions.add(4)),
            );
            let (low, high) = (
                _mm256_permute2f128_pd(first, second, 0x20),
                _mm256_permute2f128_pd(first, second, 0x31),
            );
            [
                F64x4(_mm256_unpacklo_pd(low, high)),
                F64x4(_mm256_unpackhi_pd(low, high)),
            ]
        };
        let load_lanes = LoadLanes {
            force: [load(&loads.force[0]), load(&loads.force[1])],
            torque: load(&loads.torque),
            moment: [
                [load(&loads.moment[0][0]), load(&loads.moment[0][1])],
                [load(&loads.moment[1][0]), load(&loads.moment[1][1])],
            ],
            lost_area: load(&loads.lost_area),
        };
        let lanes = advance_lanes::<F64x4, RIGID>(&mut dofs, &load_lanes, e1_lanes, constants);
        let d = dofs;
        let quarters = [
            [d.radius, d.center[0], d.center[1], d.velocity[0]],
            [d.velocity[1], d.theta, d.omega, d.eps1],
            [d.eps1_rate, d.eps2, d.eps2_rate, d.alpha],
        ];
        // A rigid grain's strains, their rates and alpha's are as they were: not written back.
        let changed = if RIGID { 2 } else { 3 };
        for (quarter, fields) in quarters.into_iter().enumerate().take(changed) {
            let rows = transpose(fields.map(|f| f.0));
            for (l, row) in rows.into_iter().enumerate() {
                _mm256_storeu_pd(base.add(13 * l + 4 * quarter), row);
            }
        }
        if !RIGID {
            let mut alpha_rate = GrainLanes::default();
            store(d.alpha_rate, &mut alpha_rate);
            for (l, &rate) in alpha_rate.0.iter().enumerate() {
                *base.add(13 * l + 12) = rate;
            }
        }

        // The checks' filter: a sum of the twelve values is finite only if each is; then the
        // strains and the speed.
        let sum = ((d.center[0] + d.center[1]) + (d.velocity[0] + d.velocity[1]))
            + ((d.theta + d.omega) + (d.eps1 + d.eps1_rate))
            + ((d.eps2 + d.eps2_rate) + (d.alpha + d.alpha_rate));
        let not_finite =
            _mm256_cmp_pd::<_CMP_NEQ_UQ>(_mm256_sub_pd(sum.0, sum.0), _mm256_setzero_pd());
        let minus_one = _mm256_set1_pd(-1.0);
        let inverted = _mm256_or_pd(
            _mm256_cmp_pd::<_CMP_LE_OQ>(d.eps1.0, minus_one),
            _mm256_cmp_pd::<_CMP_LE_OQ>(d.eps2.0, minus_one),
        );
        let speed_squared = d.velocity[0] * d.velocity[0] + d.velocity[1] * d.velocity[1];
        let runaway = _mm256_cmp_pd::<_CMP_GT_OQ>(
            speed_squared.0,
            _mm256_set1_pd(constants.update.wave_speed_squared),
        );
        let mut outcome = BlockOutcome {
            suspect: _mm256_movemask_pd(_mm256_or_pd(_mm256_or_pd(not_finite, inverted), runaway))
                as u32,
            ..BlockOutcome::default()
        };
        // The stress records: the first four `f64`s of each by a transpose, then the fifth and
        // sixth by halves, then the counts.
        let records = stresses.as_mut_ptr();
        let [xx, yy, xy] = lanes.external;
        let [sigma1, sigma2] = lanes.principal;
        let heads = transpose([xx.0, yy.0, xy.0, sigma1.0]);
        let lost_area = load(&loads.lost_area).0;
        let (even, odd) = (
            _mm256_unpacklo_pd(sigma2.0, lost_area),
            _mm256_unpackhi_pd(sigma2.0, lost_area),
        );
        let tails = [
            _mm256_castpd256_pd128(even),
            _mm256_castpd256_pd128(odd),
            _mm256_extractf128_pd::<1>(even),
            _mm256_extractf128_pd::<1>(odd),
        ];
        for l in 0..BLOCK_GRAINS {
            let record = records.add(l);
            let words = record.cast::<f64>();
            _mm256_storeu_pd(words, heads[l]);
            _mm_storeu_pd(words.add(4), tails[l]);
            (*record).contacts = contacts[l][0];
            (*record).wall_contacts = contacts[l][1];
        }
        store(lanes.area, &mut outcome.area);
        store(lanes.elastic_energy, &mut outcome.elastic_energy);
        if RIGID {
            // Circles all: their frames' first lines (`Frame::write_circle`'s centre, radius
            // `R (1 + eps1)`, mass, velocity, spin and the rigid level's dilation rate, zero)
            // by two transposes.
            let circles = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(d.eps1.0, d.eps2.0));
            if circles == 0b1111 {
                let bounding_radius = d.radius * (F64x4::splat(1.0) + d.eps1);
                let dilation = _mm256_setzero_pd();
                let heads = transpose([
                    d.center[0].0,
                    d.center[1].0,
                    bounding_radius.0,
                    lanes.mass.0,
                ]);
                let tails = transpose([d.velocity[0].0, d.velocity[1].0, d.omega.0, dilation]);
                let lines = frames.as_mut_ptr().cast::<f64>();
                for l in 0..BLOCK_GRAINS {
                    _mm256_storeu_pd(lines.add(16 * l), heads[l]);
                    _mm256_storeu_pd(lines.add(16 * l + 4), tails[l]);
                }
                outcome.circle_frames = true;
            }
            return outcome;
        }

        // The frames: the angles' sines and cosines and the affine maps in lanes
        // (`Frame::write_full_block`'s function), then each grain's two lines.
        let mut angles = BlockAngles::default();
        store(d.theta, &mut angles.theta);
        store(d.alpha, &mut angles.alpha);
        let mut states = AffineState::<GrainLanes>::default();
        store(d.eps1, &mut states.eps1);
        store(d.eps2, &mut states.eps2);
        store(d.eps1_rate, &mut states.eps1_rate);
        store(d.eps2_rate, &mut states.eps2_rate);
        store(d.alpha_rate, &mut states.alpha_rate);
        store(d.omega, &mut states.omega);
        store(d.radius, &mut states.radius);
        let (maps, gradients, directions) = super::super::affine_lanes_avx(&angles, &states);
        let bounding_radius = GrainShape::bounding_radius_of(d.radius, d.eps1, d.eps2);
        let matrix = |m: &crate::geometry::affine::Mat2<GrainLanes>| {
            transpose([
                load(&m.x_axis[0]).0,
                load(&m.x_axis[1]).0,
                load(&m.y_axis[0]).0,
                load(&m.y_axis[1]).0,
            ])
        };
        let lines = [
            transpose([
                d.center[0].0,
                d.center[1].0,
                bounding_radius.0,
                lanes.mass.0,
            ]),
            transpose([
                d.velocity[0].0,
                d.velocity[1].0,
                d.omega.0,
                // Not a circle (`Frame::circle_dilation`'s NaN).
                _mm256_set1_pd(super::super::NOT_A_CIRCLE),
            ]),
            matrix(&maps),
            matrix(&gradients),
        ];
        let frame_words = frames.as_mut_ptr().cast::<f64>();
        for (quarter, rows) in lines.into_iter().enumerate() {
            for (l, row) in rows.into_iter().enumerate() {
                _mm256_storeu_pd(frame_words.add(16 * l + 4 * quarter), row);
            }
        }
        // The directions back as `[c0, s0, c1, s1]`, `[c2, s2, c3, s3]`.
        let (cosines, sines) = (load(&directions[0]).0, load(&directions[1]).0);
        let (low, high) = (
            _mm256_unpacklo_pd(cosines, sines),
            _mm256_unpackhi_pd(cosines, sines),
        );
        let words = e1.as_mut_ptr().cast::<f64>();
        _mm256_storeu_pd(words, _mm256_permute2f128_pd(low, high, 0x20));
        _mm256_storeu_pd(words.add(4), _mm256_permute2f128_pd(low, high, 0x31));
        outcome
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat2;

    /// A record's words, as the transposes read and write them.
    fn words<T, const N: usize>(record: &T) -> [u64; N] {
        assert_eq!(std::mem::size_of::<T>(), 8 * N);
        // SAFETY: `T` is `N` words long (asserted just above), and every record here is
        // plain data whose padding, if any, the caller's values have written.
        unsafe { std::ptr::read_unaligned((record as *const T).cast::<[u64; N]>()) }
    }

    #[test]
    fn records_are_the_words_the_transposes_move() {
        // Expectation: the fields in the words the block function loads and stores, in its
        // order: a grain as `Grain::to_array`; a stress record as the three stresses, the two
        // principal stresses, the lost area, then the two counts in one word; a frame as the
        // centre, bounding radius, mass, velocity, spin, the circle flag (the low byte of a
        // word whose other bytes are padding), the map and the velocity gradient by columns.
        let value = |k: usize| 1.0 + k as f64;
        let grain = Grain {
            radius: value(0),
            center: DVec2::new(value(1), value(2)),
            velocity: DVec2::new(value(3), value(4)),
            theta: value(5),
            omega: value(6),
            eps1: value(7),
            eps1_rate: value(8),
            eps2: value(9),
            eps2_rate: value(10),
            alpha: value(11),
            alpha_rate: value(12),
        };
        assert_eq!(grain.to_array(), std::array::from_fn(value));
        assert_eq!(words::<_, 13>(&grain), grain.to_array().map(f64::to_bits));

        let stress = GrainStress {
            external: [value(0), value(1), value(2)],
            principal: [value(3), value(4)],
            lost_area: value(5),
            contacts: 7,
            wall_contacts: 9,
        };
        let stress_words = words::<_, 7>(&stress);
        assert_eq!(
            stress_words[..6],
            std::array::from_fn::<_, 6, _>(|k| value(k).to_bits())
        );
        assert_eq!(stress_words[6], 7 | 9 << 32);

        let frame = Frame {
            center: DVec2::new(value(0), value(1)),
            bounding_radius: value(2),
            mass: value(3),
            velocity: DVec2::new(value(4), value(5)),
            omega: value(6),
            circle_dilation: value(7),
            map: DMat2::from_cols_array(&[value(8), value(9), value(10), value(11)]),
            velocity_gradient: DMat2::from_cols_array(&[
                value(12),
                value(13),
                value(14),
                value(15),
            ]),
        };
        let frame_words = words::<_, 16>(&frame);
        for (k, &word) in frame_words.iter().enumerate() {
            assert_eq!(word, value(k).to_bits(), "word {k}");
        }
    }
}
