//! Robot → client server information packets (docs §5): the standard motor SIP, the SYNC
//! replies, the CONFIG packet, and everything else as an opaque frame.

use thiserror::Error;

use crate::frame::Frame;

/// Packet type of a motor SIP while the robot is stopped.
pub const SIP_STOPPED: u8 = 0x32;
/// Packet type of a motor SIP while the robot is moving.
pub const SIP_MOVING: u8 = 0x33;
/// Packet type of the CONFIG reply.
pub const CONFIG_PACKET: u8 = 0x20;

/// A packet whose layout did not match its type.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum SipError {
    /// The packet ended before a mandatory field.
    #[error("packet type {id:#04X} truncated at field {field}: {payload:02X?}")]
    Truncated {
        /// Packet type.
        id: u8,
        /// Name of the field that was missing.
        field: &'static str,
        /// The whole payload.
        payload: Vec<u8>,
    },
}

/// Little-endian field reader over a payload; every read is checked.
struct FieldReader<'a> {
    id: u8,
    all: &'a [u8],
    rest: &'a [u8],
}

impl<'a> FieldReader<'a> {
    fn new(id: u8, payload: &'a [u8]) -> Self {
        Self {
            id,
            all: payload,
            rest: payload,
        }
    }
    fn err(&self, field: &'static str) -> SipError {
        SipError::Truncated {
            id: self.id,
            field,
            payload: self.all.to_vec(),
        }
    }
    fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }
    fn u8(&mut self, field: &'static str) -> Result<u8, SipError> {
        let (b, rest) = self.rest.split_first().ok_or_else(|| self.err(field))?;
        self.rest = rest;
        Ok(*b)
    }
    fn u16(&mut self, field: &'static str) -> Result<u16, SipError> {
        match self.rest {
            [lo, hi, rest @ ..] => {
                self.rest = rest;
                Ok(u16::from_le_bytes([*lo, *hi]))
            }
            _ => Err(self.err(field)),
        }
    }
    fn i16(&mut self, field: &'static str) -> Result<i16, SipError> {
        self.u16(field).map(|v| i16::from_le_bytes(v.to_le_bytes()))
    }
    fn i8(&mut self, field: &'static str) -> Result<i8, SipError> {
        self.u8(field).map(|v| i8::from_le_bytes([v]))
    }
    fn u32(&mut self, field: &'static str) -> Result<u32, SipError> {
        match self.rest {
            [a, b, c, d, rest @ ..] => {
                self.rest = rest;
                Ok(u32::from_le_bytes([*a, *b, *c, *d]))
            }
            _ => Err(self.err(field)),
        }
    }
    /// A NUL-terminated string; a missing final NUL ends the string at the payload's end.
    fn cstr(&mut self, field: &'static str) -> Result<String, SipError> {
        if self.rest.is_empty() {
            return Err(self.err(field));
        }
        let end = self.rest.iter().position(|b| *b == 0);
        let (s, rest) = match end {
            Some(i) => (self.rest.get(..i), self.rest.get(i + 1..)),
            None => (Some(self.rest), Some(&[][..])),
        };
        self.rest = rest.unwrap_or_default();
        Ok(String::from_utf8_lossy(s.unwrap_or_default()).into_owned())
    }
    fn remaining(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.rest).to_vec()
    }
}

fn put_u16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}
fn put_i16(out: &mut Vec<u8>, v: i16) {
    out.extend_from_slice(&v.to_le_bytes());
}
fn put_cstr(out: &mut Vec<u8>, s: &str) {
    out.extend(s.bytes().filter(|b| *b != 0));
    out.push(0);
}

/// One sonar reading in a motor SIP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SonarReading {
    /// Sonar disc number (0..31).
    pub number: u8,
    /// Range in raw units (mm × RangeConvFactor, 1.0 on a P3-DX).
    pub range: u16,
}

/// Bits of the STALL_AND_BUMPERS field (docs §5.1 row 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StallBumpers(pub u16);

impl StallBumpers {
    /// Left wheel stalled (bit 0).
    #[must_use]
    pub fn left_stall(self) -> bool {
        self.0 & 0x0001 != 0
    }
    /// Right wheel stalled (bit 8).
    #[must_use]
    pub fn right_stall(self) -> bool {
        self.0 & 0x0100 != 0
    }
    /// Rear bumper segments (bits 1..7, shifted down).
    #[must_use]
    pub fn rear_bumpers(self) -> u8 {
        ((self.0 & 0x00FE) >> 1) as u8
    }
    /// Front bumper segments (bits 9..15, shifted down).
    #[must_use]
    pub fn front_bumpers(self) -> u8 {
        ((self.0 & 0xFE00) >> 9) as u8
    }
}

/// The standard motor SIP, types `0x32`/`0x33` (docs §5.1). Raw units; conversion happens in
/// [`crate::odometry`].
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct MotorSip {
    /// Type `0x33` (moving) rather than `0x32` (stopped).
    pub moving: bool,
    /// XPOS as received (only the low 15 bits are meaningful).
    pub x_raw: u16,
    /// YPOS as received (only the low 15 bits are meaningful).
    pub y_raw: u16,
    /// THPOS in AngleConvFactor units.
    pub th_raw: i16,
    /// Left wheel velocity, VelConvFactor units (mm/s).
    pub left_vel: i16,
    /// Right wheel velocity, VelConvFactor units (mm/s).
    pub right_vel: i16,
    /// Battery voltage, tenths of a volt.
    pub battery_dv: u8,
    /// Stall and bumper bits.
    pub stall_bumpers: StallBumpers,
    /// Heading servo setpoint, AngleConvFactor units.
    pub control: i16,
    /// FLAGS (bit 0 motors enabled, bits 1..4 sonar arrays on, …).
    pub flags: u16,
    /// Compass heading, 2° units.
    pub compass: u8,
    /// Sonar readings in this packet.
    pub sonar: Vec<SonarReading>,
    /// Gripper state.
    pub grip_state: u8,
    /// Selected analog port.
    pub an_port: u8,
    /// Analog value on that port.
    pub analog: u8,
    /// Digital inputs.
    pub digin: u8,
    /// Digital outputs.
    pub digout: u8,
    /// Optional ARCOS tail fields, each present only if every earlier one is.
    pub tail: SipTail,
}

/// Optional fields ARCOS appends after DIGOUT (docs §5.1 rows 18..21); later fields are kept
/// as raw bytes.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SipTail {
    /// Battery voltage, tenths of a volt, 16-bit.
    pub battery_x10: Option<u16>,
    /// Charge state (0 not charging … 4 balance).
    pub charge_state: Option<u8>,
    /// Rotational velocity, 0.1 deg/s.
    pub rot_vel: Option<i16>,
    /// Controller fault bits.
    pub fault_flags: Option<u16>,
    /// Bytes after FAULTFLAGS (LATVEL, TEMPERATURE, …), not interpreted.
    pub rest: Vec<u8>,
}

impl MotorSip {
    /// FLAGS bit 0: motors enabled.
    #[must_use]
    pub fn motors_enabled(&self) -> bool {
        self.flags & 1 != 0
    }

    /// FLAGS bits 1..4: any sonar array enabled.
    #[must_use]
    pub fn sonar_enabled(&self) -> bool {
        self.flags & 0x1E != 0
    }

    /// Parses the payload of a `0x32`/`0x33` packet.
    ///
    /// # Errors
    /// [`SipError::Truncated`] when a mandatory field (through DIGOUT) is missing. A tail field
    /// cut in half is also reported as truncated.
    pub fn parse(id: u8, payload: &[u8]) -> Result<Self, SipError> {
        let mut r = FieldReader::new(id, payload);
        let x_raw = r.u16("XPOS")?;
        let y_raw = r.u16("YPOS")?;
        let th_raw = r.i16("THPOS")?;
        let left_vel = r.i16("L VEL")?;
        let right_vel = r.i16("R VEL")?;
        let battery_dv = r.u8("BATTERY")?;
        let stall_bumpers = StallBumpers(r.u16("STALL_AND_BUMPERS")?);
        let control = r.i16("CONTROL")?;
        let flags = r.u16("FLAGS")?;
        let compass = r.u8("COMPASS")?;
        let n = r.u8("SONAR COUNT")?;
        let mut sonar = Vec::with_capacity(usize::from(n));
        for _ in 0..n {
            let number = r.u8("SONAR NUMBER")?;
            let range = r.u16("SONAR RANGE")?;
            sonar.push(SonarReading { number, range });
        }
        let grip_state = r.u8("GRIP_STATE")?;
        let an_port = r.u8("ANPORT")?;
        let analog = r.u8("ANALOG")?;
        let digin = r.u8("DIGIN")?;
        let digout = r.u8("DIGOUT")?;
        let mut tail = SipTail::default();
        if !r.is_empty() {
            tail.battery_x10 = Some(r.u16("BATTERYX10")?);
        }
        if !r.is_empty() {
            tail.charge_state = Some(r.u8("CHARGESTATE")?);
        }
        if !r.is_empty() {
            tail.rot_vel = Some(r.i16("ROTVEL")?);
        }
        if !r.is_empty() {
            tail.fault_flags = Some(r.u16("FAULTFLAGS")?);
        }
        tail.rest = r.remaining();
        Ok(MotorSip {
            moving: id == SIP_MOVING,
            x_raw,
            y_raw,
            th_raw,
            left_vel,
            right_vel,
            battery_dv,
            stall_bumpers,
            control,
            flags,
            compass,
            sonar,
            grip_state,
            an_port,
            analog,
            digin,
            digout,
            tail,
        })
    }

    /// The frame for this SIP. Tail fields are written in order up to the first absent one;
    /// at most 255 sonar readings are written.
    #[must_use]
    pub fn to_frame(&self) -> Frame {
        let mut p = Vec::with_capacity(40 + 3 * self.sonar.len());
        put_u16(&mut p, self.x_raw);
        put_u16(&mut p, self.y_raw);
        put_i16(&mut p, self.th_raw);
        put_i16(&mut p, self.left_vel);
        put_i16(&mut p, self.right_vel);
        p.push(self.battery_dv);
        put_u16(&mut p, self.stall_bumpers.0);
        put_i16(&mut p, self.control);
        put_u16(&mut p, self.flags);
        p.push(self.compass);
        let sonar = self
            .sonar
            .get(..self.sonar.len().min(255))
            .unwrap_or_default();
        p.push(u8::try_from(sonar.len()).unwrap_or(u8::MAX));
        for s in sonar {
            p.push(s.number);
            put_u16(&mut p, s.range);
        }
        p.extend_from_slice(&[
            self.grip_state,
            self.an_port,
            self.analog,
            self.digin,
            self.digout,
        ]);
        let t = &self.tail;
        if let Some(b) = t.battery_x10 {
            put_u16(&mut p, b);
            if let Some(c) = t.charge_state {
                p.push(c);
                if let Some(rv) = t.rot_vel {
                    put_i16(&mut p, rv);
                    if let Some(f) = t.fault_flags {
                        put_u16(&mut p, f);
                        p.extend_from_slice(&t.rest);
                    }
                }
            }
        }
        Frame::new(if self.moving { SIP_MOVING } else { SIP_STOPPED }, p)
    }
}

/// The robot's reply to SYNC2: name, class and subclass (docs §3.1).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RobotIdentity {
    /// Robot name (FLASH-stored).
    pub name: String,
    /// Robot class, e.g. `Pioneer`.
    pub class: String,
    /// Robot subclass, e.g. `p3dx-sh`; selects the conversion factors.
    pub subclass: String,
}

impl RobotIdentity {
    /// Parses the payload of the SYNC2 reply; missing strings are empty.
    #[must_use]
    pub fn parse(payload: &[u8]) -> Self {
        let mut r = FieldReader::new(2, payload);
        let name = r.cstr("name").unwrap_or_default();
        let class = r.cstr("class").unwrap_or_default();
        let subclass = r.cstr("subclass").unwrap_or_default();
        Self {
            name,
            class,
            subclass,
        }
    }

    /// The SYNC2 reply frame.
    #[must_use]
    pub fn to_frame(&self) -> Frame {
        let mut p = Vec::new();
        put_cstr(&mut p, &self.name);
        put_cstr(&mut p, &self.class);
        put_cstr(&mut p, &self.subclass);
        Frame::new(2, p)
    }
}

/// The CONFIG packet (type `0x20`, docs §5.3): the leading fields through WATCHDOG, which every
/// controller sends, then [`ConfigMore`] (the fields ARIA's `ArRobotConfigPacketReader` reads
/// after WATCHDOG) when the packet carries all of them, then any bytes after those.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ConfigPacket {
    /// Robot class.
    pub class: String,
    /// Robot subclass.
    pub subclass: String,
    /// Serial number.
    pub serial: String,
    /// Unused byte (old P2OS AT flag; ARIA's 4MotorsFlag).
    pub four_motors: u8,
    /// Top rotational velocity, deg/s.
    pub rot_vel_top: u16,
    /// Top translational velocity, mm/s.
    pub trans_vel_top: u16,
    /// Top rotational acceleration, deg/s².
    pub rot_accel_top: u16,
    /// Top translational acceleration, mm/s².
    pub trans_accel_top: u16,
    /// Maximum PWM.
    pub pwm_max: u16,
    /// Robot name.
    pub name: String,
    /// SIP cycle, ms.
    pub sip_cycle_ms: u8,
    /// Host baud code (0 = 9600 … 4 = 115200).
    pub host_baud: u8,
    /// AUX1 baud code.
    pub aux1_baud: u8,
    /// Gripper fitted.
    pub has_gripper: u16,
    /// Front sonar fitted.
    pub front_sonar: u16,
    /// Rear sonar fitted.
    pub rear_sonar: u8,
    /// Low-battery alarm, decivolts.
    pub low_battery_dv: u16,
    /// Encoder counts per revolution.
    pub rev_count: u16,
    /// Watchdog time, ms.
    pub watchdog_ms: u16,
    /// The fields after WATCHDOG, when the packet carries all of them.
    pub more: Option<ConfigMore>,
    /// Bytes after the last interpreted field (all of them after WATCHDOG when `more` is
    /// `None`).
    pub rest: Vec<u8>,
}

/// The CONFIG fields after WATCHDOG, in the order ARIA's `ArRobotConfigPacketReader` reads them
/// (docs §5.3). A controller that stops earlier leaves ARIA reading zeros: a TransVelMax of 0
/// makes ARIA ignore the value and send every velocity as 0.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ConfigMore {
    /// Standard motor packets (P2MPACS), 1 = on.
    pub normal_motor_packets: u8,
    /// PWM at which a wheel counts as stalled.
    pub stall_val: u16,
    /// Stall recovery time, ms.
    pub stall_count: u16,
    /// Joystick translational velocity, mm/s.
    pub joy_vel: u16,
    /// Joystick rotational velocity, deg/s.
    pub joy_rot_vel: u16,
    /// Current maximum rotational velocity (SETRV), deg/s.
    pub rot_vel_max: u16,
    /// Current maximum translational velocity (SETV), mm/s.
    pub trans_vel_max: u16,
    /// Rotational acceleration, deg/s².
    pub rot_accel: u16,
    /// Rotational deceleration, deg/s².
    pub rot_decel: u16,
    /// Rotational PID proportional term.
    pub rot_kp: u16,
    /// Rotational PID derivative term.
    pub rot_kv: u16,
    /// Rotational PID integral term.
    pub rot_ki: u16,
    /// Translational acceleration, mm/s².
    pub trans_accel: u16,
    /// Translational deceleration, mm/s².
    pub trans_decel: u16,
    /// Translational PID proportional term.
    pub trans_kp: u16,
    /// Translational PID derivative term.
    pub trans_kv: u16,
    /// Translational PID integral term.
    pub trans_ki: u16,
    /// Front bumper segments.
    pub front_bumps: u8,
    /// Rear bumper segments.
    pub rear_bumps: u8,
    /// Charger type (0 = none).
    pub has_charger: u8,
    /// Sonar cycle, ms.
    pub sonar_cycle_ms: u8,
    /// AUTOBAUD: 2 = the controller can switch baud on HOSTBAUD (ARIA's ResetBaud).
    pub autobaud: u8,
    /// Gyro type (0 = none, 1 = SIP gyro).
    pub gyro_type: u8,
    /// Drift factor.
    pub drift_factor: i16,
    /// AUX2 baud code.
    pub aux2_baud: u8,
    /// AUX3 baud code.
    pub aux3_baud: u8,
    /// Encoder ticks per mm.
    pub ticks_mm: u16,
    /// Shutdown voltage, decivolts.
    pub shutdown_voltage_dv: u16,
    /// Firmware version text.
    pub firmware_version: String,
    /// Gyro clockwise calibration.
    pub gyro_cw: u16,
    /// Gyro counter-clockwise calibration.
    pub gyro_ccw: u16,
    /// Kinematics delay, ms.
    pub kinematics_delay: u8,
    /// Top lateral velocity, mm/s (0 without lateral motion).
    pub lat_vel_top: u16,
    /// Top lateral acceleration, mm/s².
    pub lat_accel_top: u16,
    /// Current maximum lateral velocity, mm/s.
    pub lat_vel_max: u16,
    /// Lateral acceleration, mm/s².
    pub lat_accel: u16,
    /// Lateral deceleration, mm/s².
    pub lat_decel: u16,
    /// PowerBot charge threshold.
    pub powerbot_charge_threshold: u16,
    /// Power distribution board port.
    pub pdb_port: u8,
    /// Gyro rate limit, deg/s.
    pub gyro_rate_limit: u16,
    /// High temperature shutdown, °C.
    pub high_temperature_shutdown: i8,
    /// Power bits.
    pub power_bits: u16,
    /// Battery type (0 = lead acid).
    pub battery_type: u8,
    /// Low state of charge, percent.
    pub state_of_charge_low: u16,
    /// Shutdown state of charge, percent.
    pub state_of_charge_shutdown: u16,
    /// Boot loader version text.
    pub bootloader_version: String,
    /// Configuration flags.
    pub config_flags: u32,
    /// Gyro firmware version.
    pub gyro_fw_version: i16,
}

impl ConfigMore {
    fn read(r: &mut FieldReader<'_>) -> Result<Self, SipError> {
        Ok(Self {
            normal_motor_packets: r.u8("NORMALMPACS")?,
            stall_val: r.u16("STALLVAL")?,
            stall_count: r.u16("STALLCOUNT")?,
            joy_vel: r.u16("JOYVEL")?,
            joy_rot_vel: r.u16("JOYRVEL")?,
            rot_vel_max: r.u16("ROTVELMAX")?,
            trans_vel_max: r.u16("TRANSVELMAX")?,
            rot_accel: r.u16("ROTACCEL")?,
            rot_decel: r.u16("ROTDECEL")?,
            rot_kp: r.u16("ROTKP")?,
            rot_kv: r.u16("ROTKV")?,
            rot_ki: r.u16("ROTKI")?,
            trans_accel: r.u16("TRANSACCEL")?,
            trans_decel: r.u16("TRANSDECEL")?,
            trans_kp: r.u16("TRANSKP")?,
            trans_kv: r.u16("TRANSKV")?,
            trans_ki: r.u16("TRANSKI")?,
            front_bumps: r.u8("FRONTBUMPS")?,
            rear_bumps: r.u8("REARBUMPS")?,
            has_charger: r.u8("CHARGER")?,
            sonar_cycle_ms: r.u8("SONARCYCLE")?,
            autobaud: r.u8("AUTOBAUD")?,
            gyro_type: r.u8("HASGYRO")?,
            drift_factor: r.i16("DRIFTFACTOR")?,
            aux2_baud: r.u8("AUX2BAUD")?,
            aux3_baud: r.u8("AUX3BAUD")?,
            ticks_mm: r.u16("TICKSMM")?,
            shutdown_voltage_dv: r.u16("SHUTDOWNVOLTS")?,
            firmware_version: r.cstr("VERSION")?,
            gyro_cw: r.u16("GYROCW")?,
            gyro_ccw: r.u16("GYROCCW")?,
            kinematics_delay: r.u8("KINEMATICSDELAY")?,
            lat_vel_top: r.u16("LATVELTOP")?,
            lat_accel_top: r.u16("LATACCTOP")?,
            lat_vel_max: r.u16("LATVELMAX")?,
            lat_accel: r.u16("LATACCEL")?,
            lat_decel: r.u16("LATDECEL")?,
            powerbot_charge_threshold: r.u16("CHARGETHRESHOLD")?,
            pdb_port: r.u8("PDBPORT")?,
            gyro_rate_limit: r.u16("GYRORATELIMIT")?,
            high_temperature_shutdown: r.i8("HIGHTEMPSHUTDOWN")?,
            power_bits: r.u16("POWERBITS")?,
            battery_type: r.u8("BATTERYTYPE")?,
            state_of_charge_low: r.u16("LOWSTATEOFCHARGE")?,
            state_of_charge_shutdown: r.u16("SHUTDOWNSTATEOFCHARGE")?,
            bootloader_version: r.cstr("BOOTLOADERVERSION")?,
            config_flags: r.u32("CONFIGFLAGS")?,
            gyro_fw_version: r.i16("GYROFWVERSION")?,
        })
    }

    fn write(&self, p: &mut Vec<u8>) {
        p.push(self.normal_motor_packets);
        for v in [
            self.stall_val,
            self.stall_count,
            self.joy_vel,
            self.joy_rot_vel,
            self.rot_vel_max,
            self.trans_vel_max,
            self.rot_accel,
            self.rot_decel,
            self.rot_kp,
            self.rot_kv,
            self.rot_ki,
            self.trans_accel,
            self.trans_decel,
            self.trans_kp,
            self.trans_kv,
            self.trans_ki,
        ] {
            put_u16(p, v);
        }
        p.extend_from_slice(&[
            self.front_bumps,
            self.rear_bumps,
            self.has_charger,
            self.sonar_cycle_ms,
            self.autobaud,
            self.gyro_type,
        ]);
        put_i16(p, self.drift_factor);
        p.extend_from_slice(&[self.aux2_baud, self.aux3_baud]);
        put_u16(p, self.ticks_mm);
        put_u16(p, self.shutdown_voltage_dv);
        put_cstr(p, &self.firmware_version);
        put_u16(p, self.gyro_cw);
        put_u16(p, self.gyro_ccw);
        p.push(self.kinematics_delay);
        for v in [
            self.lat_vel_top,
            self.lat_accel_top,
            self.lat_vel_max,
            self.lat_accel,
            self.lat_decel,
            self.powerbot_charge_threshold,
        ] {
            put_u16(p, v);
        }
        p.push(self.pdb_port);
        put_u16(p, self.gyro_rate_limit);
        p.extend_from_slice(&self.high_temperature_shutdown.to_le_bytes());
        put_u16(p, self.power_bits);
        p.push(self.battery_type);
        put_u16(p, self.state_of_charge_low);
        put_u16(p, self.state_of_charge_shutdown);
        put_cstr(p, &self.bootloader_version);
        p.extend_from_slice(&self.config_flags.to_le_bytes());
        put_i16(p, self.gyro_fw_version);
    }
}

impl ConfigPacket {
    /// Parses a CONFIG payload. The fields after WATCHDOG become [`ConfigPacket::more`] when
    /// all of them are there, and stay raw bytes in [`ConfigPacket::rest`] otherwise.
    ///
    /// # Errors
    /// [`SipError::Truncated`] when a field through WATCHDOG is missing.
    pub fn parse(payload: &[u8]) -> Result<Self, SipError> {
        let mut r = FieldReader::new(CONFIG_PACKET, payload);
        let mut c = Self {
            class: r.cstr("TYPE")?,
            subclass: r.cstr("SUBTYPE")?,
            serial: r.cstr("SERIAL")?,
            four_motors: r.u8("FOURMOTS")?,
            rot_vel_top: r.u16("ROTVELTOP")?,
            trans_vel_top: r.u16("TRANSVELTOP")?,
            rot_accel_top: r.u16("ROTACCTOP")?,
            trans_accel_top: r.u16("TRANSACCTOP")?,
            pwm_max: r.u16("PWMMAX")?,
            name: r.cstr("NAME")?,
            sip_cycle_ms: r.u8("SIPCYCLE")?,
            host_baud: r.u8("HOSTBAUD")?,
            aux1_baud: r.u8("AUX1BAUD")?,
            has_gripper: r.u16("GRIPPER")?,
            front_sonar: r.u16("FRONTSONAR")?,
            rear_sonar: r.u8("REARSONAR")?,
            low_battery_dv: r.u16("LOWBATTERY")?,
            rev_count: r.u16("REVCOUNT")?,
            watchdog_ms: r.u16("WATCHDOG")?,
            more: None,
            rest: Vec::new(),
        };
        let after_watchdog = r.rest;
        match ConfigMore::read(&mut r) {
            Ok(more) => {
                c.more = Some(more);
                c.rest = r.remaining();
            }
            Err(_) => c.rest = after_watchdog.to_vec(),
        }
        Ok(c)
    }

    /// The CONFIG frame.
    #[must_use]
    pub fn to_frame(&self) -> Frame {
        let mut p = Vec::new();
        put_cstr(&mut p, &self.class);
        put_cstr(&mut p, &self.subclass);
        put_cstr(&mut p, &self.serial);
        p.push(self.four_motors);
        for v in [
            self.rot_vel_top,
            self.trans_vel_top,
            self.rot_accel_top,
            self.trans_accel_top,
            self.pwm_max,
        ] {
            put_u16(&mut p, v);
        }
        put_cstr(&mut p, &self.name);
        p.extend_from_slice(&[self.sip_cycle_ms, self.host_baud, self.aux1_baud]);
        put_u16(&mut p, self.has_gripper);
        put_u16(&mut p, self.front_sonar);
        p.push(self.rear_sonar);
        put_u16(&mut p, self.low_battery_dv);
        put_u16(&mut p, self.rev_count);
        put_u16(&mut p, self.watchdog_ms);
        if let Some(more) = &self.more {
            more.write(&mut p);
        }
        p.extend_from_slice(&self.rest);
        Frame::new(CONFIG_PACKET, p)
    }
}

/// A typed robot → client packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerPacket {
    /// Echo of SYNC0 or SYNC1 (the number).
    SyncEcho(u8),
    /// Reply to SYNC2.
    Identity(RobotIdentity),
    /// Standard motor SIP.
    Motor(MotorSip),
    /// CONFIG reply.
    Config(ConfigPacket),
    /// Any other packet type, unparsed.
    Other(Frame),
}

impl ServerPacket {
    /// Interprets a received frame.
    ///
    /// # Errors
    /// [`SipError`] when a motor SIP or CONFIG packet is truncated.
    pub fn from_frame(frame: Frame) -> Result<Self, SipError> {
        Ok(match frame.id {
            0 | 1 => ServerPacket::SyncEcho(frame.id),
            2 => ServerPacket::Identity(RobotIdentity::parse(&frame.payload)),
            SIP_STOPPED | SIP_MOVING => {
                ServerPacket::Motor(MotorSip::parse(frame.id, &frame.payload)?)
            }
            CONFIG_PACKET => ServerPacket::Config(ConfigPacket::parse(&frame.payload)?),
            _ => ServerPacket::Other(frame),
        })
    }

    /// The frame for this packet.
    #[must_use]
    pub fn to_frame(&self) -> Frame {
        match self {
            ServerPacket::SyncEcho(n) => Frame::new(*n, Vec::new()),
            ServerPacket::Identity(id) => id.to_frame(),
            ServerPacket::Motor(sip) => sip.to_frame(),
            ServerPacket::Config(c) => c.to_frame(),
            ServerPacket::Other(f) => f.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::FrameDecoder;

    /// docs/protocols/pioneer-aria.md §8 Example G (43 bytes, checksum wraps past 0xFFFF).
    const EXAMPLE_G: [u8; 43] = [
        0xFA, 0xFB, 0x28, 0x33, 0xE8, 0x03, 0x0C, 0x7E, 0x00, 0x04, 0xC8, 0x00, 0xC8, 0x00, 0x7D,
        0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x02, 0x00, 0x88, 0x13, 0x01, 0xB0, 0x04, 0x00,
        0x00, 0x00, 0xFF, 0x00, 0x7D, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x81, 0x0C,
    ];

    fn example_g_sip() -> MotorSip {
        MotorSip {
            moving: true,
            x_raw: 1000,
            y_raw: 0x7E0C,
            th_raw: 1024,
            left_vel: 200,
            right_vel: 200,
            battery_dv: 125,
            stall_bumpers: StallBumpers(0),
            control: 0,
            flags: 1,
            compass: 0,
            sonar: vec![
                SonarReading {
                    number: 0,
                    range: 5000,
                },
                SonarReading {
                    number: 1,
                    range: 1200,
                },
            ],
            grip_state: 0,
            an_port: 0,
            analog: 0,
            digin: 0xFF,
            digout: 0,
            tail: SipTail {
                battery_x10: Some(125),
                charge_state: Some(0),
                rot_vel: Some(0),
                fault_flags: Some(0),
                rest: vec![],
            },
        }
    }

    #[test]
    fn example_g_decodes() {
        let mut d = FrameDecoder::new();
        d.push(&EXAMPLE_G);
        let frame = d.next_frame().unwrap().unwrap();
        let ServerPacket::Motor(sip) = ServerPacket::from_frame(frame).unwrap() else {
            panic!("not a motor SIP");
        };
        assert_eq!(sip, example_g_sip());
        assert!(sip.motors_enabled());
        assert_eq!(d.dropped_bytes(), 0);
    }

    #[test]
    fn example_g_sonar_reaches_the_ring() {
        // Example G's sonar: disc 0 at 5000 mm (no echo), disc 1 at 1200 mm.
        let mut d = FrameDecoder::new();
        d.push(&EXAMPLE_G);
        let frame = d.next_frame().unwrap().unwrap();
        let ServerPacket::Motor(sip) = ServerPacket::from_frame(frame).unwrap() else {
            panic!("not a motor SIP");
        };
        let mut ring = crate::sonar::SonarRing::p3dx();
        assert!(ring.update(&sip, &crate::odometry::ConversionFactors::P3DX_SH));
        assert_eq!(ring.updated, 0b11);
        let ranges: Vec<(f64, f64)> = ring.readings().map(|(d, r)| (d.heading_rad, r)).collect();
        assert_eq!(ranges.len(), 2);
        assert!(
            (ranges[0].0 - 90f64.to_radians()).abs() < 1e-12 && (ranges[0].1 - 5.0).abs() < 1e-12
        );
        assert!(
            (ranges[1].0 - 50f64.to_radians()).abs() < 1e-12 && (ranges[1].1 - 1.2).abs() < 1e-12
        );
    }

    #[test]
    fn example_g_encodes() {
        assert_eq!(example_g_sip().to_frame().encode().unwrap(), EXAMPLE_G);
    }

    #[test]
    fn example_f_identity() {
        // §8 Example F: MobileSim's SYNC2 reply.
        let bytes: [u8; 29] = [
            0xFA, 0xFB, 0x1A, 0x02, 0x4D, 0x6F, 0x62, 0x69, 0x6C, 0x65, 0x53, 0x69, 0x6D, 0x00,
            0x50, 0x69, 0x6F, 0x6E, 0x65, 0x65, 0x72, 0x00, 0x70, 0x33, 0x64, 0x78, 0x00, 0x93,
            0x45,
        ];
        let id = RobotIdentity {
            name: "MobileSim".into(),
            class: "Pioneer".into(),
            subclass: "p3dx".into(),
        };
        assert_eq!(id.to_frame().encode().unwrap(), bytes);
        let mut d = FrameDecoder::new();
        d.push(&bytes);
        let f = d.next_frame().unwrap().unwrap();
        assert_eq!(
            ServerPacket::from_frame(f).unwrap(),
            ServerPacket::Identity(id)
        );
    }

    #[test]
    fn stall_and_bumper_bits() {
        // §5.1 row 7: low byte bit0 left stall, bits1-7 rear; high byte bit8 right stall, 9-15 front.
        let s = StallBumpers(0b1010_0001_0000_0101);
        assert!(s.left_stall());
        assert!(s.right_stall());
        assert_eq!(s.rear_bumpers(), 0b10);
        assert_eq!(s.front_bumpers(), 0b101_0000);
    }

    #[test]
    fn truncated_sip_is_an_error_with_payload() {
        let payload = &EXAMPLE_G[4..20];
        let err = MotorSip::parse(0x33, payload).unwrap_err();
        assert!(matches!(err, SipError::Truncated { field: "FLAGS", .. }));
    }

    #[test]
    fn config_round_trip() {
        let c = ConfigPacket {
            class: "Pioneer".into(),
            subclass: "p3dx-sh".into(),
            serial: "EMU".into(),
            rot_vel_top: 500,
            trans_vel_top: 2200,
            name: "rfloc".into(),
            sip_cycle_ms: 100,
            watchdog_ms: 2000,
            rest: vec![1, 2, 3],
            ..ConfigPacket::default()
        };
        let f = c.to_frame();
        assert_eq!(
            ServerPacket::from_frame(f).unwrap(),
            ServerPacket::Config(c)
        );
        let c = ConfigPacket {
            class: "Pioneer".into(),
            more: Some(ConfigMore {
                trans_vel_max: 750,
                firmware_version: "1.0".into(),
                bootloader_version: "boot".into(),
                config_flags: 0x0102_0304,
                high_temperature_shutdown: -5,
                ..ConfigMore::default()
            }),
            rest: vec![9],
            ..ConfigPacket::default()
        };
        let f = c.to_frame();
        assert_eq!(
            ServerPacket::from_frame(f).unwrap(),
            ServerPacket::Config(c)
        );
    }

    #[test]
    fn unknown_type_is_other() {
        let f = Frame::new(0x90, vec![1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(
            ServerPacket::from_frame(f.clone()).unwrap(),
            ServerPacket::Other(f)
        );
    }
}
