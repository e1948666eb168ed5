"""Heading, turn-rate and speed controllers of the Rover-like autopilot, and each vehicle's mixer.

Pure control logic (state in ``ControllerState``, parameters from sitl.parameters), no I/O. It follows
ArduPilot Rover's attitude control:
- heading error -> desired turn rate (ATC_STR_ANG_P, capped at ATC_STR_RAT_MAX) -> steering by a
  turn-rate PI with feed-forward (ATC_STR_RAT_FF/P/I), integrator frozen while saturated;
- speed over ground ALONG THE HEADING -> throttle by a PI with CRUISE_SPEED/CRUISE_THROTTLE
  feed-forward (ATC_SPEED_P/I); a cross current is not corrected, it sets the boat sideways;
- a desired speed of exactly zero is the stop controller (AR_AttitudeControl::get_throttle_out_stop):
  brake until slower than STOP_SPEED_MPS (ATC_STOP_SPEED), then throttle zero for as long as the
  demand stays zero, so a stopped boat drifts with the current, whatever its speed;
- heading + speed targets (GUIDED velocity setpoints): steer and drive at once, no pivot logic (as
  ArduPilot's HeadingAndSpeed submode);
- driving to a point (GUIDED position targets, RTL, loiter outside its radius): forward or reverse by
  LOIT_TYPE at LOIT_SPEED_GAIN x (distance - radius); the skid-steer boat (DIFF_THRUST) slows by
  cos(heading error) and pivots beyond WP_PIVOT_ANGLE (zero speed, turn at up to WP_PIVOT_RATE, until
  within PIVOT_EXIT_RAD), as ArduPilot's waypoint navigation does; inside the radius the boat drifts
  (stop controller).

Mixers (commands in [-1, 1], steering > 0 turns to starboard):
- DIFF_THRUST (port, stbd) = (throttle + steering, throttle - steering), scaled back fairly when saturated;
- RUDDER (throttle, rudder) = (throttle, +-steering), the rudder reversed when the desired speed is
  astern (not while braking); a rudder turns the boat only with way through the water;
- VECTORED (port, stbd, bow, stern): the pair drives (throttle, throttle), the tunnel thrusters steer
  and push sideways (lateral +- steering), so it turns on the spot with a pure couple; the lateral
  channel is used only to hold a point (loiter), so in GUIDED it behaves like the others.

Conventions: NED positions [m] and velocities [m/s], headings from north clockwise [rad], rates [rad/s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl.config import VehicleKind
from sitl.guided import Navigation
from sitl.parameters import ParamStore
from sitl.sensors import wrap_pi

STOP_SPEED_MPS = 0.1  # ATC_STOP_SPEED: below this a zero speed demand turns the throttle off [m/s]
PIVOT_EXIT_RAD = math.radians(10.0)  # a pivot turn ends within this heading error [rad]
REVERSE_HYSTERESIS_RAD = math.radians(30.0)  # loiter flips forward/reverse only past 90 deg + this


@dataclass
class ControllerState:
    """Integrators and the last outputs of the controllers."""

    steer_integral: float = 0.0
    speed_integral: float = 0.0
    lateral_integral: float = 0.0
    desired_heading: float | None = None  # [rad]
    desired_speed: float = 0.0  # [m/s]
    throttle: float = 0.0  # [-1, 1]
    steering: float = 0.0  # [-1, 1]
    lateral: float = 0.0  # [-1, 1] (VECTORED)
    reversing: bool = False  # loiter is backing toward its point
    pivoting: bool = False  # a skid-steer pivot turn is under way
    stopped: bool = False  # the stop controller has brought the boat below STOP_SPEED_MPS (latched)


class Steering:
    """The controllers of one boat of a given kind; each call returns that kind's actuator commands."""

    def __init__(self, kind: VehicleKind, params: ParamStore):
        self.kind = kind
        self.params = params
        self.state = ControllerState()

    def zero(self) -> tuple[float, ...]:
        """All actuators off."""
        return (0.0,) * (4 if self.kind is VehicleKind.VECTORED else 2)

    def reset(self, heading: float | None = None) -> None:
        self.state = ControllerState(desired_heading=heading)

    # ---- guided demands ---------------------------------------------------------------------------
    def heading_speed(self, heading: float, speed: float, nav: Navigation, dt: float) -> tuple[float, ...]:
        """Hold ``heading`` [rad] at ``speed`` over ground along it [m/s] (negative = astern).

        No pivot logic here (ArduPilot's HeadingAndSpeed submode: calc_steering_to_heading and
        calc_throttle only): the boat steers while it drives; at speed 0 the stop controller turns the
        throttle off and a skid-steer or vectored boat turns on the spot.
        """
        self.state.pivoting = False
        steering = self._steer_to_heading(heading, nav, dt)
        return self._mix(self._throttle(speed, nav, dt), steering, 0.0)

    def turn_rate_speed(self, rate: float, speed: float, nav: Navigation, dt: float) -> tuple[float, ...]:
        """Turn at ``rate`` [rad/s] at ``speed`` over ground along the heading [m/s]."""
        self.state.desired_heading = None
        self.state.pivoting = False
        rate_max = math.radians(self.params.get("ATC_STR_RAT_MAX"))
        rate = min(rate_max, max(-rate_max, rate))
        return self._mix(self._throttle(speed, nav, dt), self._steer_rate(rate, nav, dt), 0.0)

    def hold(
        self, point: tuple[float, float], speed_cap: float, radius: float, nav: Navigation, dt: float
    ) -> tuple[float, ...]:
        """ArduPilot Rover boat loiter about ``point`` (N, E) [m] with ``radius`` [m], speed <= speed_cap."""
        ctl = self.state
        p = self.params
        dn, de = point[0] - nav.n, point[1] - nav.e
        distance = math.hypot(dn, de)
        heading = ctl.desired_heading if ctl.desired_heading is not None else nav.psi
        if distance <= radius:  # drift: keep the heading, stop (throttle off once slow)
            ctl.pivoting = False
            steering = self._steer_to_heading(heading, nav, dt)
            return self._mix(self._throttle(0.0, nav, dt), steering, self._lateral(0.0, nav, dt))
        speed = min((distance - radius) * p.get("LOIT_SPEED_GAIN"), speed_cap)
        if self.kind is VehicleKind.VECTORED:  # holonomic: move toward the point, keep the heading
            c, s = math.cos(nav.psi), math.sin(nav.psi)
            forward = speed * (c * dn + s * de) / distance
            sideways = speed * (-s * dn + c * de) / distance
            steering = self._steer_to_heading(heading, nav, dt)
            throttle = self._throttle_pi(forward, nav, dt)
            return self._mix(throttle, steering, self._lateral(sideways, nav, dt))
        heading = math.atan2(de, dn)
        error = wrap_pi(heading - nav.psi)
        loiter_type = round(p.get("LOIT_TYPE"))
        if loiter_type == 0:  # reverse when the point is behind; hysteresis keeps it from chattering
            flip = math.pi / 2 + REVERSE_HYSTERESIS_RAD  # the current direction is kept up to 120 deg off
            reversing = abs(error) > flip if not ctl.reversing else abs(wrap_pi(error + math.pi)) <= flip
            if reversing != ctl.reversing:
                ctl.speed_integral = 0.0  # the speed loop's integrator belongs to the old direction
                ctl.reversing = reversing
        else:
            ctl.reversing = loiter_type == 2
        if ctl.reversing:
            heading = wrap_pi(heading + math.pi)
            error = wrap_pi(heading - nav.psi)
            speed = -speed
        if self.kind is VehicleKind.DIFF_THRUST:  # skid steering: slow while turning, pivot beyond the angle
            speed = 0.0 if self._pivot(error) else speed * max(math.cos(error), 0.0)
        steering = self._steer_to_heading(heading, nav, dt)
        return self._mix(self._throttle_pi(speed, nav, dt), steering, 0.0)

    # ---- controllers --------------------------------------------------------------------------------
    def _pivot(self, error: float) -> bool:
        """Whether a pivot turn is under way for this heading error [rad] (DIFF_THRUST only)."""
        ctl = self.state
        angle = math.radians(self.params.get("WP_PIVOT_ANGLE"))
        if self.kind is not VehicleKind.DIFF_THRUST or angle <= 0.0:
            ctl.pivoting = False
        elif ctl.pivoting:
            ctl.pivoting = abs(error) > PIVOT_EXIT_RAD
        else:
            ctl.pivoting = abs(error) > angle
        return ctl.pivoting

    def _steer_to_heading(self, heading: float, nav: Navigation, dt: float) -> float:
        """Heading error -> desired turn rate (ATC_STR_ANG_P, capped) -> steering."""
        p = self.params
        self.state.desired_heading = heading
        rate_max = math.radians(p.get("ATC_STR_RAT_MAX"))
        if self.state.pivoting:
            rate_max = min(rate_max, math.radians(p.get("WP_PIVOT_RATE")))
        rate = min(rate_max, max(-rate_max, p.get("ATC_STR_ANG_P") * wrap_pi(heading - nav.psi)))
        return self._steer_rate(rate, nav, dt)

    def _steer_rate(self, rate: float, nav: Navigation, dt: float) -> float:
        """Turn-rate PI with feed-forward (ATC_STR_RAT_FF/P/I); the integrator stops at saturation."""
        p = self.params
        ctl = self.state
        error = rate - nav.r
        out = p.get("ATC_STR_RAT_FF") * rate + p.get("ATC_STR_RAT_P") * error + ctl.steer_integral
        if abs(out) < 1.0 or out * error < 0:
            ctl.steer_integral += p.get("ATC_STR_RAT_I") * error * dt
        return min(1.0, max(-1.0, out))

    def _throttle(self, speed: float, nav: Navigation, dt: float) -> float:
        """Speed over ground along the heading -> throttle; exactly zero speed is the stop controller."""
        ctl = self.state
        if speed != 0.0:
            ctl.stopped = False
            return self._throttle_pi(speed, nav, dt)
        forward = nav.vn * math.cos(nav.psi) + nav.ve * math.sin(nav.psi)
        # ArduPilot's get_throttle_out_stop: stopped once slower than the stop speed, and it stays
        # stopped (throttle off, the boat drifts with any current) while the demand stays zero
        ctl.stopped = ctl.stopped or abs(forward) <= STOP_SPEED_MPS
        if ctl.stopped:
            ctl.desired_speed = 0.0
            ctl.speed_integral = 0.0
            return 0.0
        return self._throttle_pi(0.0, nav, dt)

    def _throttle_pi(self, speed: float, nav: Navigation, dt: float) -> float:
        """Forward speed over ground PI with CRUISE_SPEED/CRUISE_THROTTLE feed-forward."""
        p = self.params
        ctl = self.state
        ctl.desired_speed = speed
        forward = nav.vn * math.cos(nav.psi) + nav.ve * math.sin(nav.psi)
        error = speed - forward
        cruise_speed = p.get("CRUISE_SPEED")
        feed_forward = speed / cruise_speed * p.get("CRUISE_THROTTLE") / 100.0 if cruise_speed > 0 else 0.0
        out = feed_forward + p.get("ATC_SPEED_P") * error + ctl.speed_integral
        if abs(out) < 1.0 or out * error < 0:
            ctl.speed_integral += p.get("ATC_SPEED_I") * error * dt
        return min(1.0, max(-1.0, out))

    def _lateral(self, speed: float, nav: Navigation, dt: float) -> float:
        """Sideways speed over ground (to starboard) PI for the tunnel thrusters; 0 off VECTORED."""
        if self.kind is not VehicleKind.VECTORED:
            return 0.0
        p = self.params
        ctl = self.state
        sideways = -nav.vn * math.sin(nav.psi) + nav.ve * math.cos(nav.psi)
        if speed == 0.0 and (ctl.stopped or abs(sideways) <= STOP_SPEED_MPS):
            ctl.lateral_integral = 0.0
            return 0.0
        error = speed - sideways
        out = p.get("ATC_SPEED_P") * error + ctl.lateral_integral
        if abs(out) < 1.0 or out * error < 0:
            ctl.lateral_integral += p.get("ATC_SPEED_I") * error * dt
        return min(1.0, max(-1.0, out))

    def _mix(self, throttle: float, steering: float, lateral: float) -> tuple[float, ...]:
        ctl = self.state
        ctl.throttle, ctl.steering, ctl.lateral = throttle, steering, lateral
        if self.kind is VehicleKind.RUDDER:
            return throttle, -steering if ctl.desired_speed < 0 else steering  # astern on purpose, not braking
        if self.kind is VehicleKind.DIFF_THRUST:
            return _skid_mix(throttle, steering)
        return throttle, throttle, *_skid_mix(lateral, steering)


def _skid_mix(common: float, differential: float) -> tuple[float, float]:
    """(common + differential, common - differential), both scaled back fairly when saturated."""
    saturation = abs(common) + abs(differential)
    if saturation > 1.0:
        common /= saturation
        differential /= saturation
    # clipped as well: the scaled sum can round to 1 + 1 ulp
    return min(1.0, max(-1.0, common + differential)), min(1.0, max(-1.0, common - differential))
