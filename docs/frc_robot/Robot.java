// The roboRIO side of docs/frc_bridge.md, in Java (WPILib TimedRobot, NT4 publishers and
// subscribers). Not compiled in this repository (no WPILib Java toolchain here): paste it
// into a WPILib project and adapt channels, gear ratio, sensor offsets, motor controllers.
// Each loop, in this order: read the sensors (and the time), take the newest command that
// has arrived, set the motors, publish the loop's reading as one value stamped with the
// sensors' time, flush.
package frc.robot;

import edu.wpi.first.networktables.DoubleArrayPublisher;
import edu.wpi.first.networktables.DoubleArraySubscriber;
import edu.wpi.first.networktables.NetworkTableInstance;
import edu.wpi.first.networktables.PubSubOption;
import edu.wpi.first.networktables.TimestampedDoubleArray;
import edu.wpi.first.wpilibj.AnalogPotentiometer;
import edu.wpi.first.wpilibj.DriverStation;
import edu.wpi.first.wpilibj.Encoder;
import edu.wpi.first.wpilibj.PowerDistribution;
import edu.wpi.first.wpilibj.RobotController;
import edu.wpi.first.wpilibj.TimedRobot;
import edu.wpi.first.wpilibj.motorcontrol.PWMTalonSRX;

public class Robot extends TimedRobot {
  static final double GEAR_RATIO = 159.3;           // motor turns per joint turn
  static final double ENCODER_CPR = 2048;           // encoder counts per motor turn
  static final long COMMAND_TIMEOUT_US = 100_000;   // a pair drives until time_us + this
  static final int VOLTAGE_SIZE = 3;                // [time_us, V_s, V_e], or
  static final int PROFILE_HEAD = 6, PROFILE_POINT = 6;  // [time_us, step_s, kp_s, kd_s, kp_e,
  // kd_e, then (q_s, q_e, qd_s, qd_e, ff_s, ff_e) per setpoint]

  final NetworkTableInstance nt = NetworkTableInstance.getDefault();
  final PubSubOption[] fast = {
    PubSubOption.periodic(0.005), PubSubOption.keepDuplicates(true), PubSubOption.sendAll(true)
  };
  final DoubleArrayPublisher readingPub =
      nt.getDoubleArrayTopic("/arm/robot/reading").publish(fast);
  final DoubleArraySubscriber commandSub =
      nt.getDoubleArrayTopic("/arm/command/motors").subscribe(new double[] {}, fast);
  double[] held = null;                             // the command in charge
  final java.util.ArrayList<double[]> pending = new java.util.ArrayList<>();  // profiles, not begun

  final PWMTalonSRX[] shoulderMotors = {new PWMTalonSRX(0), new PWMTalonSRX(1)};
  final PWMTalonSRX elbowMotor = new PWMTalonSRX(2);
  final AnalogPotentiometer shoulderPot = new AnalogPotentiometer(0, 2 * Math.PI, -Math.PI / 2);
  final AnalogPotentiometer elbowPot = new AnalogPotentiometer(1, 2 * Math.PI, -Math.PI);
  final Encoder[] encoders = {new Encoder(0, 1), new Encoder(2, 3)};
  final PowerDistribution pdh = new PowerDistribution();

  @Override
  public void robotInit() {
    for (Encoder encoder : encoders) {
      encoder.setDistancePerPulse(2 * Math.PI / (ENCODER_CPR * GEAR_RATIO));
    }
  }

  static boolean isCommand(double[] c) {
    return c.length == VOLTAGE_SIZE
        || (c.length > PROFILE_HEAD && (c.length - PROFILE_HEAD) % PROFILE_POINT == 0 && c[1] > 0);
  }

  static int points(double[] c) {
    return (c.length - PROFILE_HEAD) / PROFILE_POINT;
  }

  /** A pair acts on arrival; a profile from half a step before its setpoint 0. */
  static double beginsUs(double[] c) {
    return c.length == VOLTAGE_SIZE ? Double.NEGATIVE_INFINITY : c[0] - 0.5e6 * c[1];
  }

  /** Refused on arrival from then on: a pair's instant, a profile's last setpoint's, + the
   * timeout. A pair also stops driving then; a profile never does (held at its end). */
  static double staleUs(double[] c) {
    double lastUs = c.length == VOLTAGE_SIZE ? c[0] : c[0] + 1e6 * c[1] * (points(c) - 1);
    return lastUs + COMMAND_TIMEOUT_US;
  }

  /** A pair as it is. A profile: setpoint k nearest now, q_sp = q_k + qd_k (t - t_k) (past
   * the last, that one held at rest), V = ff_k + kp (q_sp - q) + kd (qd_sp - qd). */
  static double[] voltageFor(double[] c, long nowUs, double[] q, double[] qd) {
    if (c.length == VOLTAGE_SIZE) {
      return new double[] {c[1], c[2]};
    }
    double step = c[1], since = (nowUs - c[0]) * 1e-6;
    int k = (int) Math.min(Math.max(Math.floor(since / step + 0.5), 0), points(c) - 1);
    int b = PROFILE_HEAD + PROFILE_POINT * k;
    double tau = Math.min(Math.max(since - k * step, -0.5 * step), 0.5 * step);
    boolean atRest = k == points(c) - 1 && since - k * step > 0.5 * step;
    double[] v = new double[2];
    for (int j = 0; j < 2; j++) {
      double qdSp = atRest ? 0.0 : c[b + 2 + j];
      v[j] = c[b + 4 + j] + c[2 + 2 * j] * (c[b + j] + qdSp * tau - q[j])
          + c[3 + 2 * j] * (qdSp - qd[j]);
    }
    return v;
  }

  @Override
  public void robotPeriodic() {
    // 1. The sensors, and the instant they were read: on a roboRIO the FPGA clock is the
    //    NT server's clock, the time base of the whole contract.
    long nowUs = RobotController.getFPGATime();
    double[] q = {shoulderPot.get(), elbowPot.get()};
    double[] qd = {encoders[0].getRate(), encoders[1].getRate()};
    double[] enc = {encoders[0].getDistance(), encoders[1].getDistance()};
    double[] current = {pdh.getCurrent(0), pdh.getCurrent(2)};       // one motor a joint
    double supply = pdh.getCurrent(0) + pdh.getCurrent(1) + pdh.getCurrent(2);
    double bus = RobotController.getBatteryVoltage();
    boolean enabled = DriverStation.isEnabled();

    // 2. The commands that have arrived, in order, unless stale: a pair takes charge at once;
    //    a profile from half a step before its start. Disabled: none.
    for (TimestampedDoubleArray value : commandSub.readQueue()) {
      double[] c = value.value;
      if (!isCommand(c) || nowUs >= staleUs(c)) {
        continue;
      }
      if (c.length == VOLTAGE_SIZE) {
        held = c;
        pending.clear();
      } else {
        pending.add(c);
      }
    }
    int begun = -1;
    for (int i = 0; i < pending.size(); i++) {
      if (nowUs >= beginsUs(pending.get(i))) {
        begun = i;
      }
    }
    if (begun >= 0) {
      held = pending.get(begun);
      pending.subList(0, begun + 1).clear();
    }
    if (!enabled) {
      held = null;
      pending.clear();
    }

    // 3. The voltage from now on: a pair until its timeout, then 0 V; a profile played.
    double[] v = {0.0, 0.0};
    if (held != null && (held.length != VOLTAGE_SIZE || nowUs < staleUs(held))) {
      v = voltageFor(held, nowUs, q, qd);
    }
    for (int j = 0; j < 2; j++) {
      v[j] = Math.max(-bus, Math.min(bus, v[j]));
    }
    for (PWMTalonSRX motor : shoulderMotors) {
      motor.setVoltage(v[0]);
    }
    elbowMotor.setVoltage(v[1]);

    // 4. The loop's reading, whole, stamped with the sensors' instant; sent at once.
    readingPub.set(new double[] {
      nowUs, enabled ? 1 : 0, q[0], q[1], qd[0], qd[1], enc[0], enc[1],
      current[0], current[1], bus, supply, v[0], v[1]}, nowUs);
    nt.flush();
  }
}
