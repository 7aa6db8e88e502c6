//! A hobby servo as the twin drives it: a proportional controller on the output shaft's
//! potentiometer, a DC motor's torque-speed line, a deadband, and gear backlash.
//!
//! Everything here is in the servo horn's own units (rad, N·m at the horn); the twin maps
//! a joint to its horn through the linkage ([`crate::drive::Drive`]).
//!
//! The model, each physics step:
//! - **controller:** error `e = target − θ` (θ: the output shaft, where the pot is);
//!   duty `u = clamp(e / proportional_band, −1, 1)`, and `u = 0` while `|e|` is inside
//!   half the deadband;
//! - **motor:** torque `τ = τ_stall · (u − ω / ω₀)`, the line from stall torque at rest to
//!   no-load speed ω₀ at full duty (so a free servo turns at ω₀ = 60° / 0.2 s, and a
//!   loaded one slower);
//! - **backlash:** the motor side sits `b` of free play behind the output. While the
//!   play is being taken up (the motor reversing), no torque reaches the output and the
//!   motor side turns at `u · ω₀`; once a flank meets, the torque passes;
//! - **gear friction:** the datasheets' stall torque and speed are measured at the horn,
//!   through the gear train's friction, so the motor makes that friction on top of the
//!   line's torque while it drives (the physics charges it as the joint's
//!   `frictionloss`, which is also what holds a limp servo).

/// A servo model's constants, in the horn's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoSpec {
    /// The model's name, for logs and docs.
    pub name: &'static str,
    /// Stall torque at the horn (N·m).
    pub stall_torque_nm: f64,
    /// No-load speed at the horn (rad/s).
    pub no_load_speed_rad_s: f64,
    /// Deadband: the width of the error band (rad) inside which the controller does not
    /// drive the motor.
    pub deadband_rad: f64,
    /// Gear backlash at the horn (rad).
    pub backlash_rad: f64,
    /// Error (rad) at which the controller's duty reaches 100 %.
    pub proportional_band_rad: f64,
    /// Inertia of the rotor and gear train, seen at the horn (kg·m²): MuJoCo's
    /// `armature`.
    pub rotor_inertia_kg_m2: f64,
    /// The gear train's friction at the horn (N·m): what turning a limp servo by its
    /// horn takes (MuJoCo's `frictionloss`). An unpowered arm droops against it.
    pub gear_friction_nm: f64,
}

/// kgf·cm → N·m.
const KGF_CM: f64 = 0.098_066_5;

impl ServoSpec {
    /// TowerPro MG995 at 4.8 V, its datasheet: stall torque 8.5 kgf·cm, 0.2 s/60°, dead
    /// band 5 µs (0.48° at the Servo library's 544–2400 µs for 180°). Backlash 1°
    /// (metal gears; the datasheet gives none: our estimate), proportional band 5°,
    /// a 10 ms mechanical time constant and 0.02 N·m of gear friction (our estimates;
    /// see docs/twin.md).
    pub const MG995: ServoSpec = ServoSpec {
        name: "MG995",
        stall_torque_nm: 8.5 * KGF_CM,
        no_load_speed_rad_s: std::f64::consts::FRAC_PI_3 / 0.2,
        deadband_rad: 5.0 * (180.0 / 1856.0) * std::f64::consts::PI / 180.0,
        backlash_rad: 1.0 * std::f64::consts::PI / 180.0,
        proportional_band_rad: 5.0 * std::f64::consts::PI / 180.0,
        rotor_inertia_kg_m2: 8.5 * KGF_CM * 0.010 / (std::f64::consts::FRAC_PI_3 / 0.2),
        gear_friction_nm: 0.02,
    };

    /// TowerPro SG90 at 4.8 V, its datasheet: stall torque 1.8 kgf·cm, 0.12 s/60° (the
    /// figure config/arm.yaml's motion limits use; some revisions print 0.1 s), dead
    /// band 10 µs (0.97°). Backlash 2° (plastic gears: our estimate), proportional band
    /// 5°, 10 ms mechanical time constant, 0.005 N·m of gear friction.
    pub const SG90: ServoSpec = ServoSpec {
        name: "SG90",
        stall_torque_nm: 1.8 * KGF_CM,
        no_load_speed_rad_s: std::f64::consts::FRAC_PI_3 / 0.12,
        deadband_rad: 10.0 * (180.0 / 1856.0) * std::f64::consts::PI / 180.0,
        backlash_rad: 2.0 * std::f64::consts::PI / 180.0,
        proportional_band_rad: 5.0 * std::f64::consts::PI / 180.0,
        rotor_inertia_kg_m2: 1.8 * KGF_CM * 0.010 / (std::f64::consts::FRAC_PI_3 / 0.12),
        gear_friction_nm: 0.005,
    };

    /// The same servo with its stall torque scaled (a weak supply, a worn motor: the
    /// twin's `torque_scale`).
    pub fn with_torque_scale(mut self, scale: f64) -> ServoSpec {
        self.stall_torque_nm *= scale;
        self
    }

    /// The controller's duty (−1 … 1) for an error (rad).
    pub fn duty(&self, error_rad: f64) -> f64 {
        if error_rad.abs() <= self.deadband_rad / 2.0 {
            0.0
        } else {
            (error_rad / self.proportional_band_rad).clamp(-1.0, 1.0)
        }
    }
}

/// One servo's state between physics steps: where the motor side is in the backlash.
#[derive(Clone, Debug)]
pub struct Servo {
    spec: ServoSpec,
    /// The motor side's angle (rad, horn units): the output's angle ± half the backlash.
    motor_rad: f64,
}

impl Servo {
    /// A servo at rest, its gears meshed at the output's angle `pos_rad`.
    pub fn new(spec: ServoSpec, pos_rad: f64) -> Servo {
        Servo {
            spec,
            motor_rad: pos_rad,
        }
    }

    /// The constants.
    pub fn spec(&self) -> &ServoSpec {
        &self.spec
    }

    /// The torque (N·m at the horn) the servo applies to its output over the next step
    /// of `dt` s, steering to `target_rad` from the output's angle `pos_rad` and speed
    /// `vel_rad_s`.
    pub fn torque(&mut self, target_rad: f64, pos_rad: f64, vel_rad_s: f64, dt: f64) -> f64 {
        let s = &self.spec;
        let half = s.backlash_rad / 2.0;
        let duty = s.duty(target_rad - pos_rad);
        let torque = s.stall_torque_nm * (duty - vel_rad_s / s.no_load_speed_rad_s);
        // the motor side, turning unloaded, over this step: if it meets the flank it
        // pushes towards, the gears mesh and the torque passes (a hair of tolerance: the
        // flank is met when the play is taken up to rounding)
        let free = self.motor_rad + duty * s.no_load_speed_rad_s * dt - pos_rad;
        let flank = half - 1e-12;
        if (free >= flank && torque > 0.0) || (free <= -flank && torque < 0.0) {
            self.motor_rad = pos_rad + free.clamp(-half, half);
            return torque + s.gear_friction_nm * torque.signum();
        }
        // in the play: the output feels nothing
        self.motor_rad = pos_rad + free.clamp(-half, half);
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A horn with inertia `j` (kg·m²) and a constant load torque, integrated
    /// semi-implicitly: the time (s) at which it first comes within 1° of `target` (or
    /// of `target` less the 3° its load is seen to hold it short of) and its final position.
    fn step_response(
        spec: ServoSpec,
        j: f64,
        load: f64,
        target: f64,
        seconds: f64,
    ) -> (Option<f64>, f64) {
        let dt = 1e-4;
        let mut servo = Servo::new(spec, 0.0);
        let (mut pos, mut vel) = (0.0, 0.0);
        let mut reached = None;
        let inertia = j + spec.rotor_inertia_kg_m2;
        for k in 0..(seconds / dt) as usize {
            let tau = servo.torque(target, pos, vel, dt) + load;
            vel += tau / inertia * dt;
            pos += vel * dt;
            let tol = if load == 0.0 { 1f64 } else { 3f64 }.to_radians();
            if reached.is_none() && (target - pos).abs() < tol {
                reached = Some((k + 1) as f64 * dt);
            }
        }
        (reached, pos)
    }

    #[test]
    fn a_free_mg995_turns_60_degrees_in_about_0_2_s() {
        let (t, end) = step_response(ServoSpec::MG995, 1e-4, 0.0, 60f64.to_radians(), 1.0);
        let t = t.unwrap();
        assert!((0.18..=0.22).contains(&t), "{t} s");
        // and stays inside its deadband and backlash
        let band = (ServoSpec::MG995.deadband_rad + ServoSpec::MG995.backlash_rad) / 2.0;
        assert!(
            (end - 60f64.to_radians()).abs() <= band,
            "{}",
            end.to_degrees()
        );
    }

    #[test]
    fn a_loaded_servo_is_slower_and_holds_short_of_its_target() {
        let spec = ServoSpec::MG995;
        let load = -0.5 * spec.stall_torque_nm; // half stall, against the motion
        let target = 60f64.to_radians();
        let (t_free, _) = step_response(spec, 1e-3, 0.0, target, 2.0);
        let (t_loaded, end) = step_response(spec, 1e-3, load, target, 2.0);
        assert!(
            t_loaded.unwrap() > t_free.unwrap() * 1.5,
            "{t_loaded:?} vs {t_free:?}"
        );
        // it holds where its duty balances the load: half the proportional band short
        let droop = target - end;
        let expected = 0.5 * spec.proportional_band_rad;
        assert!(
            (droop - expected).abs() < 0.1 * expected,
            "{} deg",
            droop.to_degrees()
        );
    }

    #[test]
    fn beyond_stall_torque_the_load_wins() {
        let spec = ServoSpec::SG90;
        let (_, end) = step_response(spec, 1e-4, -1.2 * spec.stall_torque_nm, 0.0, 0.5);
        assert!(end < -0.5, "{end}");
    }

    #[test]
    fn inside_the_deadband_the_motor_does_not_drive() {
        let s = ServoSpec::MG995;
        assert_eq!(s.duty(0.4 * s.deadband_rad), 0.0);
        assert_eq!(s.duty(-0.4 * s.deadband_rad), 0.0);
        assert!(s.duty(0.6 * s.deadband_rad) > 0.0);
        assert_eq!(s.duty(1.0), 1.0);
        assert_eq!(s.duty(-1.0), -1.0);
    }

    #[test]
    fn reversing_takes_up_the_backlash_before_torque_passes() {
        let s = ServoSpec::MG995;
        let mut servo = Servo::new(s, 0.0);
        // push positive: meshed at once (the gears start meshed on both flanks' middle,
        // so the first push crosses half the play first)
        let dt = 1e-3;
        let mut steps_without_torque = 0;
        while servo.torque(1.0, 0.0, 0.0, dt) == 0.0 {
            steps_without_torque += 1;
            assert!(steps_without_torque < 100);
        }
        // now reverse: the whole play (b at u·ω₀) passes with no torque at the output
        let mut reverse_steps = 0;
        while servo.torque(-1.0, 0.0, 0.0, dt) == 0.0 {
            reverse_steps += 1;
            assert!(reverse_steps < 100);
        }
        let expected = (s.backlash_rad / (s.no_load_speed_rad_s * dt)).ceil() as i32;
        assert!(
            (reverse_steps - expected).abs() <= 1,
            "{reverse_steps} vs {expected}"
        );
        assert!(reverse_steps > steps_without_torque);
    }

    #[test]
    fn torque_scale_scales_the_stall_torque() {
        let half = ServoSpec::MG995.with_torque_scale(0.5);
        assert_eq!(half.stall_torque_nm, ServoSpec::MG995.stall_torque_nm * 0.5);
    }
}
