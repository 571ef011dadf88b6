#!/usr/bin/python3
"""Blind test cases for `diffdyn diagnose`, simulated without any project code.

Each case is a joint-space CSV (t, trajectory, q*, qd*, tau*) simulated from one
of the analytic models of shared/reference/model_conventions.md (pendulum,
cart-pole, Panda) plus at most one named effect, and a truth.json describing
what was hidden. The dynamics, the Panda recursive Newton-Euler, the
controller, the integrator and the excitation are all written here from the
reference sheets only.

Usage:
  /usr/bin/python3 generate.py --out DIR --seed S [--cases N] [--controls K]
      [--static M] [--realism ideal|real]
  /usr/bin/python3 generate.py --check     # Panda dynamics self-checks
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np

G_PANDA = 9.80665
KINDS = ("viscous", "coulomb", "stribeck", "offset", "spring", "armature",
         "gain", "delay", "payload")
SYSTEMS = ("pendulum", "cartpole", "panda")
RATES_HZ = (100.0, 200.0, 250.0, 500.0, 1000.0)
EXCITATIONS = ("sines", "chirp", "p2p")
COULOMB_VSCALE = 0.01          # tanh(qd / 0.01) of the contract
DT_MAX = 1e-3                  # largest internal RK4 step (s)
WARMUP_S = 0.5                 # simulated before t = 0 and dropped
RATIO_RANGE = (4.0, 24.0)      # target effect RMS / noise std (contract 3-30)
NOISE_FRAC = (0.002, 0.02)     # torque noise std / torque range
VELOCITY_KINDS = ("viscous", "coulomb", "stribeck")
DELAY_MAX_S = 0.1 + 1e-12      # largest drawn delay (s)
REALISM_LEVELS = ("ideal", "real")
LOW_RATE_HZ = (50.0, 100.0)    # `real`: drawn with probability LOW_RATE_P
LOW_RATE_P = 0.3
JITTER_MAX = 0.05              # `real`: sample-time jitter / period, at most
LOWPASS_FRAC = (0.1, 0.4)      # `real`: torque sensor cutoff / sample rate
QUANT_FRAC = (0.2, 1.0)        # `real`: torque step / low-passed noise std
ENCODER_COUNT = (1e-5, 1e-4)   # `real`: position quantum (rad or m)
BACKDIFF_P = 0.5               # `real`: probability that qd is a difference
CREEP_MAX = 1e-3               # `real` static: drift velocity bound (rad/s)

# ----------------------------------------------------------------------------
# Small vector helpers (arrays of shape (..., 3)).
# ----------------------------------------------------------------------------


def cross(a, b):
  """Cross product of broadcastable (..., 3) arrays."""
  ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
  bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
  return np.stack((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx),
                  axis=-1)


def rot_to_child(c, s, ca, sa, v):
  """R^T v for R = RotX(alpha) RotZ(theta) (parent -> child coordinates)."""
  u1 = ca * v[..., 1] + sa * v[..., 2]
  u2 = -sa * v[..., 1] + ca * v[..., 2]
  return np.stack((c * v[..., 0] + s * u1, -s * v[..., 0] + c * u1, u2), -1)


def rot_to_parent(c, s, ca, sa, v):
  """R v for R = RotX(alpha) RotZ(theta) (child -> parent coordinates)."""
  w0 = c * v[..., 0] - s * v[..., 1]
  w1 = s * v[..., 0] + c * v[..., 1]
  return np.stack((w0, ca * w1 - sa * v[..., 2], sa * w1 + ca * v[..., 2]), -1)


# ----------------------------------------------------------------------------
# Models: each gives mass_bias(q, qd) -> (M (B,n,n), h (B,n)) with
# M(q) qdd + h(q, qd) = tau, and inverse(q, qd, qdd) -> tau.
# ----------------------------------------------------------------------------


class Pendulum:
  """Point mass m at distance l, q = 0 hanging down (model_conventions.md)."""

  name = "pendulum"
  n = 1

  def __init__(self, m=1.0, l=0.5, g=9.81):
    self.m, self.l, self.g = m, l, g

  def with_payload(self, dm):
    """The same pendulum with an extra point mass dm at the tip."""
    return Pendulum(self.m + dm, self.l, self.g)

  def mass_bias(self, q, qd):
    """Mass matrix and bias torque, batched over the leading axis."""
    ml = self.m * self.l
    mass = np.full(q.shape[:-1] + (1, 1), ml * self.l)
    return mass, ml * self.g * np.sin(q)

  def inverse(self, q, qd, qdd):
    """Inverse dynamics tau = M qdd + h."""
    mass, h = self.mass_bias(q, qd)
    return mass[..., 0] * qdd + h


class CartPole:
  """Fully actuated cart-pole: x (m), theta = 0 upright, point-mass pole."""

  name = "cartpole"
  n = 2

  def __init__(self, m_cart=0.57, m_pole=0.127, l=0.1683, g=9.81):
    self.mc, self.mp, self.l, self.g = m_cart, m_pole, l, g

  def with_payload(self, dm):
    """The same cart-pole with an extra point mass dm at the pole end."""
    return CartPole(self.mc, self.mp + dm, self.l, self.g)

  def mass_bias(self, q, qd):
    """Mass matrix H and bias [-mp l sin th thd^2, -mp g l sin th]."""
    th, thd = q[..., 1], qd[..., 1]
    mpl = self.mp * self.l
    mass = np.empty(q.shape[:-1] + (2, 2))
    mass[..., 0, 0] = self.mc + self.mp
    mass[..., 0, 1] = mass[..., 1, 0] = mpl * np.cos(th)
    mass[..., 1, 1] = mpl * self.l
    h = np.stack((-mpl * np.sin(th) * thd ** 2,
                  -mpl * self.g * np.sin(th)), -1)
    return mass, h

  def inverse(self, q, qd, qdd):
    """Inverse dynamics tau = H qdd + h."""
    mass, h = self.mass_bias(q, qd)
    return np.einsum("...ij,...j->...i", mass, qdd) + h


PANDA_DH = ((0.0, 0.333, 0.0), (0.0, 0.0, -math.pi / 2),
            (0.0, 0.316, math.pi / 2), (0.0825, 0.0, math.pi / 2),
            (-0.0825, 0.384, -math.pi / 2), (0.0, 0.0, math.pi / 2),
            (0.088, 0.0, math.pi / 2))          # (a_{i-1}, d_i, alpha_{i-1})
PANDA_FLANGE_D = 0.107
PANDA_MASS = (4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555,
              0.735522)
PANDA_COM = ((3.875e-3, 2.081e-3, 0.0), (-3.141e-3, -2.872e-2, 3.495e-3),
             (2.7518e-2, 3.9252e-2, -6.6502e-2),
             (-5.317e-2, 1.04419e-1, 2.7454e-2),
             (-1.1953e-2, 4.1065e-2, -3.8437e-2),
             (6.0149e-2, -1.4117e-2, -1.0517e-2),
             (1.0517e-2, -4.252e-3, 6.1597e-2))
PANDA_INERTIA = (  # Ixx, Ixy, Ixz, Iyy, Iyz, Izz (barycentric, frame i axes)
    (7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03),
    (7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02),
    (3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02,
     1.0830e-02),
    (2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02),
    (3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03),
    (1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03),
    (1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04,
     4.8150e-03))
PANDA_QMIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175,
                       -2.8973])
PANDA_QMAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525,
                       2.8973])
PANDA_DQMAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
PANDA_DDQMAX = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])


def inertia_matrix(row):
  """3x3 tensor from (Ixx, Ixy, Ixz, Iyy, Iyz, Izz)."""
  ixx, ixy, ixz, iyy, iyz, izz = row
  return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def add_point_mass(m, c, inertia, dm, p):
  """Merges a point mass dm at p into a body (m, COM c, barycentric I)."""
  mt = m + dm
  ct = (m * c + dm * p) / mt
  d1, d2 = c - ct, p - ct
  shift = (m * (d1 @ d1 * np.eye(3) - np.outer(d1, d1)) +
           dm * (d2 @ d2 * np.eye(3) - np.outer(d2, d2)))
  return mt, ct, inertia + shift


class Panda:
  """Panda rigid-body dynamics (Craig DH, Gaz et al. Tables VIII/IX), RNEA."""

  name = "panda"
  n = 7

  def __init__(self, payload=0.0):
    self.payload = payload
    self.mass = np.array(PANDA_MASS)
    self.com = np.array(PANDA_COM)
    self.inertia = np.array([inertia_matrix(r) for r in PANDA_INERTIA])
    if payload:
      flange = np.array([0.0, 0.0, PANDA_FLANGE_D])
      m7, c7, i7 = add_point_mass(self.mass[6], self.com[6], self.inertia[6],
                                  payload, flange)
      self.mass[6], self.com[6], self.inertia[6] = m7, c7, i7
    self.p = np.array([[a, -math.sin(al) * d, math.cos(al) * d]
                       for a, d, al in PANDA_DH])
    self.ca = np.array([math.cos(al) for _, _, al in PANDA_DH])
    self.sa = np.array([math.sin(al) for _, _, al in PANDA_DH])

  def with_payload(self, dm):
    """The Panda with a point mass dm at the flange (0.107 m along z7)."""
    return Panda(self.payload + dm)

  def rnea(self, q, qd, qdd, gscale):
    """Recursive Newton-Euler, batched over the leading axis.

    Args:
      q, qd, qdd: (N, 7) joint positions, velocities, accelerations.
      gscale: (N,) multiplier of gravity (1 normally, 0 for M columns).

    Returns:
      (N, 7) joint torques.
    """
    nb = q.shape[0]
    cq, sq = np.cos(q), np.sin(q)
    w = np.zeros((nb, 3))
    wd = np.zeros((nb, 3))
    acc = np.zeros((nb, 3))
    acc[:, 2] = G_PANDA * gscale      # base accelerates up = gravity down
    forces, moments = [], []
    for i in range(7):
      c, s, ca, sa, p = cq[:, i], sq[:, i], self.ca[i], self.sa[i], self.p[i]
      acc = rot_to_child(c, s, ca, sa,
                         acc + cross(wd, p) + cross(w, cross(w, p)))
      w_r = rot_to_child(c, s, ca, sa, w)
      wd = rot_to_child(c, s, ca, sa, wd)
      wd[:, 0] += w_r[:, 1] * qd[:, i]
      wd[:, 1] -= w_r[:, 0] * qd[:, i]
      wd[:, 2] += qdd[:, i]
      w = w_r
      w[:, 2] += qd[:, i]
      com = self.com[i]
      acc_c = acc + cross(wd, com) + cross(w, cross(w, com))
      iw = w @ self.inertia[i].T
      forces.append(self.mass[i] * acc_c)
      moments.append(wd @ self.inertia[i].T + cross(w, iw))
    tau = np.empty((nb, 7))
    f = forces[6]
    n = moments[6] + cross(self.com[6], forces[6])
    tau[:, 6] = n[:, 2]
    for i in range(5, -1, -1):
      c, s = cq[:, i + 1], sq[:, i + 1]
      ca, sa = self.ca[i + 1], self.sa[i + 1]
      f_r = rot_to_parent(c, s, ca, sa, f)
      n = (moments[i] + rot_to_parent(c, s, ca, sa, n) +
           cross(self.com[i], forces[i]) + cross(self.p[i + 1], f_r))
      f = f_r + forces[i]
      tau[:, i] = n[:, 2]
    return tau

  def mass_bias(self, q, qd):
    """M(q) from 7 unit-acceleration RNEA columns and h in one batch."""
    nb = q.shape[0]
    eye = np.repeat(np.eye(7), nb, axis=0)
    q_all = np.tile(q, (8, 1))
    qd_all = np.concatenate((qd, np.zeros((7 * nb, 7))))
    qdd_all = np.concatenate((np.zeros((nb, 7)), eye))
    gs = np.concatenate((np.ones(nb), np.zeros(7 * nb)))
    tau = self.rnea(q_all, qd_all, qdd_all, gs)
    mass = tau[nb:].reshape(7, nb, 7).transpose(1, 2, 0)
    return mass, tau[:nb]

  def inverse(self, q, qd, qdd):
    """Inverse dynamics for any leading shape."""
    shape = q.shape
    flat = [x.reshape(-1, 7) for x in (q, qd, qdd)]
    tau = self.rnea(*flat, np.ones(flat[0].shape[0]))
    return tau.reshape(shape)


def make_model(system):
  """Model with the contract's default parameters."""
  return {"pendulum": Pendulum, "cartpole": CartPole, "panda": Panda}[system]()


def joint_box(system):
  """Per-joint (lo, hi, amp_max, v_max, a_max) arrays for excitations."""
  if system == "pendulum":
    return tuple(np.array([v]) for v in (-2.0, 2.0, 1.5, 6.0, 40.0))
  if system == "cartpole":
    return (np.array([-0.4, -1.0]), np.array([0.4, 1.0]),
            np.array([0.35, 0.9]), np.array([1.5, 6.0]), np.array([8.0, 40.0]))
  lo, hi = PANDA_QMIN + 0.25, PANDA_QMAX - 0.25
  return (lo, hi, np.minimum(1.0, (hi - lo) / 2), 0.6 * PANDA_DQMAX,
          0.4 * PANDA_DDQMAX)


# ----------------------------------------------------------------------------
# Reference trajectories: callables t -> (q, qd, qdd), each t.shape + (B, n).
# ----------------------------------------------------------------------------


def draw_centres(rng, box, shape):
  """Centres and amplitude budgets inside each joint's box."""
  lo, hi, amp_max = box[0], box[1], box[2]
  budget = rng.uniform(0.3, 1.0, shape) * amp_max
  centre = rng.uniform(lo + budget, hi - budget)
  return centre, budget


def sines_reference(rng, box, nb, n):
  """Sum of 2-4 sines per joint, 0.1-2 Hz, random phases."""
  k = int(rng.integers(2, 5))
  centre, budget = draw_centres(rng, box, (nb, n))
  share = rng.dirichlet(np.ones(k), (nb, n))
  amp = budget[..., None] * share
  omega = 2 * np.pi * rng.uniform(0.1, 2.0, (nb, n, k))
  phase = rng.uniform(0, 2 * np.pi, (nb, n, k))

  def ref(t, scale=None):
    a = amp if scale is None else amp * scale[..., None]
    arg = omega * np.asarray(t, float)[..., None, None, None] + phase
    sn, cs = np.sin(arg), np.cos(arg)
    return (centre + (a * sn).sum(-1), (a * omega * cs).sum(-1),
            -(a * omega ** 2 * sn).sum(-1))
  return ref


def chirp_reference(rng, box, nb, n, length):
  """Linear chirp per joint from 0.1-0.4 Hz to 0.8-2 Hz over the length."""
  centre, amp = draw_centres(rng, box, (nb, n))
  f0 = rng.uniform(0.1, 0.4, (nb, n))
  f1 = rng.uniform(0.8, 2.0, (nb, n))
  phase0 = rng.uniform(0, 2 * np.pi, (nb, n))

  def ref(t, scale=None):
    a = amp if scale is None else amp * scale
    tt = np.asarray(t, float)[..., None, None]
    ph = 2 * np.pi * (f0 * tt + (f1 - f0) * tt ** 2 / (2 * length)) + phase0
    dph = 2 * np.pi * (f0 + (f1 - f0) * tt / length)
    ddph = 2 * np.pi * (f1 - f0) / length
    sn, cs = np.sin(ph), np.cos(ph)
    return centre + a * sn, a * cs * dph, -a * sn * dph ** 2 + a * cs * ddph
  return ref


def p2p_reference(rng, box, nb, n, length):
  """Minimum-jerk moves between random waypoints with 0.2-1.5 s holds."""
  lo, hi, _, vmax, amax = box
  waypoints = [rng.uniform(lo, hi, (nb, n))]
  starts, durations = [], []
  t = rng.uniform(0.2, 1.5)
  while t < length:
    nxt = rng.uniform(lo, hi, (nb, n))
    delta = np.abs(nxt - waypoints[-1])
    dur = max(0.4, float(np.max(1.875 * delta / vmax)),
              float(np.max(np.sqrt(5.774 * delta / amax))))
    dur *= rng.uniform(1.0, 1.5)
    waypoints.append(nxt)
    starts.append(t)
    durations.append(dur)
    t += dur + rng.uniform(0.2, 1.5)
  wp = np.array(waypoints)
  starts, durations = np.array(starts), np.array(durations)

  def ref(t, scale=None):
    del scale  # p2p moves are sized by their durations
    t = np.asarray(t, float)
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0,
                len(starts) - 1)
    dur = durations[k]
    u = np.clip((t - starts[k]) / dur, 0.0, 1.0)
    pos = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
    vel = (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / dur
    acc = (60 * u - 180 * u ** 2 + 120 * u ** 3) / dur ** 2
    step = wp[k + 1] - wp[k]
    ex = (Ellipsis, None, None)
    return wp[k] + step * pos[ex], step * vel[ex], step * acc[ex]
  return ref


def make_reference(rng, system, excitation, nb, length):
  """Reference within joint, velocity and acceleration limits."""
  box = joint_box(system)
  n = len(box[0])
  if excitation == "p2p":
    return p2p_reference(rng, box, nb, n, length)
  raw = (sines_reference(rng, box, nb, n) if excitation == "sines" else
         chirp_reference(rng, box, nb, n, length))
  grid = np.arange(-WARMUP_S, length, 0.005)
  _, qd, qdd = raw(grid)
  scale = np.minimum(1.0, np.minimum(box[3] / np.abs(qd).max(0),
                                     box[4] / np.abs(qdd).max(0)))
  return lambda t: raw(t, scale)


# ----------------------------------------------------------------------------
# Effects and the closed-loop simulation.
# ----------------------------------------------------------------------------


def friction_shape(kind, params, qd):
  """tau_effect / F_c for the velocity-dependent effects (per joint)."""
  if kind == "viscous":
    return qd
  sign = np.tanh(qd / COULOMB_VSCALE)
  if kind == "coulomb":
    return sign
  ratio = params["F_s"] / params["F_c"]
  return (1 + (ratio - 1) * np.exp(-(qd / params["v_s"]) ** 2)) * sign


def effect_torque(effect, q, qd):
  """Joint-space tau_effect of the per-joint state effects, (B, n)."""
  tau = np.zeros_like(q)
  if effect is None or effect["kind"] not in (
      "viscous", "coulomb", "stribeck", "offset", "spring"):
    return tau
  j, kind, val = effect["joint"] - 1, effect["kind"], effect["value"]
  if kind == "offset":
    tau[:, j] = -val
  elif kind == "spring":
    tau[:, j] = val * q[:, j]
  else:
    tau[:, j] = val * friction_shape(kind, effect["params"], qd[:, j])
  return tau


class ClosedLoop:
  """Computed-torque PD tracking on the nominal model, driving the plant."""

  def __init__(self, model, effect, ref, wn):
    self.model, self.effect, self.ref = model, effect, ref
    self.kp, self.kd = wn ** 2, 2.0 * wn
    kind = effect["kind"] if effect else None
    self.plant = (model.with_payload(effect["value"]) if kind == "payload"
                  else None)
    self.gain = effect["value"] if kind == "gain" else 1.0

  def command(self, t, q, qd):
    """Controller torque and the nominal (M, h) at the state."""
    qr, qdr, qddr = self.ref(t)
    mass, h = self.model.mass_bias(q, qd)
    v = qddr + self.kd * (qdr - qd) + self.kp * (qr - q)
    return np.einsum("bij,bj->bi", mass, v) + h, mass, h

  def accel(self, q, qd, tau_app, mass, h):
    """Plant acceleration under the applied torque."""
    if self.plant is not None:
      mass, h = self.plant.mass_bias(q, qd)
    if self.effect and self.effect["kind"] == "armature":
      mass = mass.copy()
      j = self.effect["joint"] - 1
      mass[:, j, j] += self.effect["value"]
    rhs = tau_app - h - effect_torque(self.effect, q, qd)
    return np.linalg.solve(mass, rhs[..., None])[..., 0]

  def plant_accel(self, q, qd, tau_app):
    """Plant acceleration under a given applied torque (zero-order hold)."""
    mass, h = ((None, None) if self.plant is not None else
               self.model.mass_bias(q, qd))
    return self.accel(q, qd, tau_app, mass, h)

  def stage(self, t, q, qd, tau_app=None):
    """One RK4 stage: (qdd, tau_cmd); tau_app given only under delay."""
    cmd, mass, h = self.command(t, q, qd)
    if tau_app is None:
      tau_app = self.gain * cmd
    return self.accel(q, qd, tau_app, mass, h), cmd


def simulate(loop, period, n_sub, n_samples, delay_s):
  """RK4 at period / n_sub; returns q, qd, qdd, tau_measured (T, B, n).

  The measured torque is always the controller command: under `gain` the
  actuator delivers k times it, under `delay` it delivers it d seconds late.
  """
  dt = period / n_sub
  n_warm = int(round(WARMUP_S / period))
  q, qd, _ = loop.ref(-n_warm * period)
  out = {k: np.empty((n_samples,) + q.shape) for k in ("q", "qd", "qdd", "tau")}
  lag = int(round(delay_s / dt))      # >= 2 steps whenever delay_s > 0
  hist = []
  for s in range((n_warm + n_samples) * n_sub):
    t = s * dt - n_warm * period
    if lag:
      cmd, mass, h = loop.command(t, q, qd)
      hist.append(cmd)
      a0, a1 = hist[max(0, s - lag)], hist[max(0, s + 1 - lag)]
      k1 = loop.accel(q, qd, a0, mass, h)
      applied = (0.5 * (a0 + a1), 0.5 * (a0 + a1), a1)
    else:
      k1, cmd = loop.stage(t, q, qd)
      applied = (None, None, None)
    k, r = divmod(s, n_sub)
    if r == 0 and k >= n_warm:
      for name, val in (("q", q), ("qd", qd), ("qdd", k1), ("tau", cmd)):
        out[name][k - n_warm] = val
    k2, _ = loop.stage(t + dt / 2, q + dt / 2 * qd, qd + dt / 2 * k1,
                       applied[0])
    k3, _ = loop.stage(t + dt / 2, q + dt / 2 * (qd + dt / 2 * k1),
                       qd + dt / 2 * k2, applied[1])
    k4, _ = loop.stage(t + dt, q + dt * (qd + dt / 2 * k2), qd + dt * k3,
                       applied[2])
    q = q + dt * (qd + dt / 6 * (k1 + k2 + k3))
    qd = qd + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
  return out


def per_trajectory(ref):
  """A reference taking one time per trajectory: t (B,) -> 3 x (B, n)."""
  def each(t):
    idx = np.arange(len(t))
    return tuple(x[idx, idx] for x in ref(t))
  return each


def delayed_index(times, k, x, period):
  """Per trajectory, the last sample j <= k with times[j] <= x (else 0)."""
  cols = np.arange(times.shape[1])
  j = np.floor((x - times[0]) / period).astype(int) + 1
  j = np.clip(j, 0, k)
  for _ in range(4):              # jitter < period / 2: at most 2 steps back
    j = j - ((times[j, cols] > x) & (j > 0))
  return j


def held_torque(loop, cmds, times, k, s, delay_s, period):
  """Torque the actuator applies at stage times s (B,) in interval k."""
  if not delay_s:
    return loop.gain * cmds[k]
  j = delayed_index(times, k, s - delay_s, period)
  return cmds[j, np.arange(times.shape[1])]


def rk4_held(loop, q, qd, t, h, torque):
  """One RK4 step of the plant; torque(stage time) gives the applied torque."""
  hc = h[:, None]
  k1 = loop.plant_accel(q, qd, torque(t))
  k2 = loop.plant_accel(q + hc / 2 * qd, qd + hc / 2 * k1, torque(t + h / 2))
  k3 = loop.plant_accel(q + hc / 2 * (qd + hc / 2 * k1), qd + hc / 2 * k2,
                        torque(t + h / 2))
  k4 = loop.plant_accel(q + hc * (qd + hc / 2 * k2), qd + hc * k3,
                        torque(t + h))
  return (q + hc * (qd + hc / 6 * (k1 + k2 + k3)),
          qd + hc / 6 * (k1 + 2 * k2 + 2 * k3 + k4), k1)


def simulate_zoh(loop, times, n_warm, n_sub, delay_s, period):
  """Sampled control with zero-order hold, RK4 at n_sub steps per interval.

  The controller computes its torque only at the sample instants times
  (K, B) (one column per trajectory, jittered) and holds it until the next;
  under `delay` the actuator applies the held command d seconds late. The
  first n_warm samples are dropped. Returns q, qd, qdd (just after the
  sample), tau (the held command) as (K - n_warm, B, n) arrays.
  """
  q, qd, _ = loop.ref(times[0])
  n_rec = times.shape[0] - n_warm
  cmds = np.empty((times.shape[0],) + q.shape)
  out = {k: np.empty((n_rec,) + q.shape) for k in ("q", "qd", "qdd", "tau")}
  for k in range(times.shape[0]):
    cmds[k] = loop.command(times[k], q, qd)[0]

    def torque(s, k=k):
      return held_torque(loop, cmds, times, k, s, delay_s, period)
    if k >= n_warm:
      out["q"][k - n_warm], out["qd"][k - n_warm] = q, qd
      out["tau"][k - n_warm] = cmds[k]
      out["qdd"][k - n_warm] = loop.plant_accel(q, qd, torque(times[k]))
    if k + 1 == times.shape[0]:
      break
    h = (times[k + 1] - times[k]) / n_sub
    for r in range(n_sub):
      q, qd, _ = rk4_held(loop, q, qd, times[k] + r * h, h, torque)
  return out


# ----------------------------------------------------------------------------
# Sensor models of the `real` level.
# ----------------------------------------------------------------------------


def log_uniform(rng, lo, hi):
  """One draw, log-uniform in [lo, hi]."""
  return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def draw_realism(rng, static):
  """Per-case realism parameters of the `real` level (recorded in truth)."""
  real = {"level": "real", "zero_order_hold": not static,
          "tau_lowpass_cutoff_frac_of_rate": float(rng.uniform(*LOWPASS_FRAC)),
          "tau_quant_step_frac_of_std": float(rng.uniform(*QUANT_FRAC)),
          "velocity": ("backward_difference" if rng.random() < BACKDIFF_P
                       else "simulated_plus_white_noise"),
          "encoder_count": log_uniform(rng, *ENCODER_COUNT),
          "jitter_frac_of_period": float(rng.uniform(0.0, JITTER_MAX))}
  real["low_rate"] = bool(not static and rng.random() < LOW_RATE_P)
  return real


def quant_factor(realism):
  """Final torque noise std / low-passed noise std (adds step^2 / 12)."""
  return math.sqrt(1.0 + realism["tau_quant_step_frac_of_std"] ** 2 / 12.0)


def jittered_times(rng, n, nb, period, jitter, n_warm=0):
  """(n_warm + n, nb) sample instants; the first recorded one is exactly 0."""
  base = (np.arange(n_warm + n) - n_warm)[:, None] * period
  e = rng.uniform(-jitter, jitter, (n_warm + n, nb)) * period
  e[n_warm] = 0.0
  return base + e


def lowpass_noise(rng, times, sigma, cutoff_hz):
  """White noise through a first-order low-pass, sampled at times (T, B).

  This is an Ornstein-Uhlenbeck process sampled exactly, started from its
  stationary law, so its std is sigma (n,) at any sampling. Returns (T, B, n).
  """
  w = rng.normal(0, 1, times.shape + (len(sigma),))
  a = np.exp(-2 * np.pi * cutoff_hz * np.diff(times, axis=0))[..., None]
  b = np.sqrt(1 - a ** 2)
  y = np.empty_like(w)
  y[0] = w[0]
  for k in range(1, len(w)):
    y[k] = a[k - 1] * y[k - 1] + b[k - 1] * w[k]
  return y * sigma


def quantise(x, step):
  """Rounds x to multiples of step (broadcast)."""
  return step * np.round(x / step)


def measure_real(rng, realism, rate, times, clean, sigma, q_std, qd_std):
  """Noisy, filtered, quantised measurements of clean q, qd, tau (T, B, n).

  sigma is the low-passed torque noise std per joint; the torque step is
  realism's fraction of it. Returns (measured dict, diagnostics dict).
  """
  cutoff = realism["tau_lowpass_cutoff_frac_of_rate"] * rate
  step = realism["tau_quant_step_frac_of_std"] * sigma
  tau = quantise(clean["tau"] + lowpass_noise(rng, times, sigma, cutoff), step)
  count = realism["encoder_count"]
  q = quantise(clean["q"] + rng.normal(0, q_std, clean["q"].shape), count)
  if realism["velocity"] == "backward_difference":
    qd = np.empty_like(q)
    qd[1:] = np.diff(q, axis=0) / np.diff(times, axis=0)[..., None]
    qd[0] = qd[1]
  else:
    qd = clean["qd"] + rng.normal(0, qd_std, q.shape)
  n = q.shape[-1]
  diag = {"tau_lowpass_cutoff_hz": cutoff, "tau_quant_step": step.tolist(),
          "tau_noise_empirical_std": rms(
              (tau - clean["tau"]).reshape(-1, n)).tolist(),
          "qd_error_empirical_std": rms(
              (qd - clean["qd"]).reshape(-1, n)).tolist()}
  return {"q": q, "qd": qd, "tau": tau}, diag


# ----------------------------------------------------------------------------
# Case design.
# ----------------------------------------------------------------------------


def rms(x, axis=0):
  """Root mean square along an axis."""
  return np.sqrt(np.mean(np.square(x), axis=axis))


def shifted_diff(tau, lag):
  """tau(t) - tau(t - lag samples) within each trajectory, (T-lag, B, n)."""
  return tau[lag:] - tau[:-lag]


def draw_gain(rng):
  """Gain in [0.8, 0.95] or [1.05, 1.25]."""
  return float(rng.uniform(0.8, 0.95) if rng.random() < 0.5 else
               rng.uniform(1.05, 1.25))


def size_per_joint(rng, kind, model, sample, sigma):
  """Effect dict for a per-joint or payload effect, sized by RMS / noise."""
  q, qd, qdd, tau = sample
  ratio = float(np.exp(rng.uniform(*np.log(RATIO_RANGE))))
  if kind == "payload":
    unit = model.with_payload(1.0).inverse(q, qd, qdd) - tau
    value = ratio / float(np.max(rms(unit.reshape(-1, model.n)) / sigma))
    return {"kind": kind, "joint": 0, "value": value,
            "params": {"mass": value}}
  j = int(rng.integers(model.n))
  params = {}
  if kind == "stribeck":
    params = {"F_c": 1.0, "F_s": float(rng.uniform(1.3, 2.0)),
              "v_s": float(rng.uniform(0.05, 0.25))}
  if kind in VELOCITY_KINDS:
    unit = friction_shape(kind, params, qd[..., j])
  else:
    unit = {"offset": np.ones_like(q[..., j]), "spring": q[..., j],
            "armature": qdd[..., j]}[kind]
  value = ratio * sigma[j] / float(rms(unit.ravel()))
  if kind == "offset":
    value *= rng.choice((-1.0, 1.0))
  names = {"viscous": "b", "coulomb": "F_c", "offset": "tau_0",
           "spring": "k", "armature": "I_a"}
  if kind == "stribeck":
    params = {"F_c": value, "F_s": value * params["F_s"],
              "v_s": params["v_s"]}
  else:
    params = {names[kind]: value}
  return {"kind": kind, "joint": j + 1, "value": float(value),
          "params": params}


def feasible_fraction(rng, contrast):
  """Noise fraction f making contrast / f a ratio in RATIO_RANGE, or None."""
  lo = max(NOISE_FRAC[0], contrast / RATIO_RANGE[1])
  hi = min(NOISE_FRAC[1], contrast / RATIO_RANGE[0])
  return float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if lo < hi else None


def size_system_wide(rng, kind, sample, period, trange):
  """(effect, noise fraction) for gain or delay, or None if not feasible."""
  tau = sample[3]
  if kind == "gain":
    k = draw_gain(rng)
    contrast = float(np.max(abs(1 - 1 / k) * rms(tau.reshape(-1, tau.shape[-1]))
                            / trange))
    frac = feasible_fraction(rng, contrast)
    return None if frac is None else (
        {"kind": kind, "joint": 0, "value": k, "params": {"k": k}}, frac)
  lags = [m for m in range(2, 7)
          if 0.002 - 1e-12 <= m * period <= DELAY_MAX_S]
  for lag in rng.permutation(lags):
    diff = shifted_diff(tau, int(lag))
    contrast = float(np.max(rms(diff.reshape(-1, tau.shape[-1])) / trange))
    frac = feasible_fraction(rng, contrast)
    if frac is not None:
      d = float(lag * period)
      return {"kind": kind, "joint": 0, "value": d, "params": {"d": d}}, frac
  return None


def stiffness(model, effect, sample):
  """Largest |d qdd / d qd| the friction effect adds (1/s)."""
  if effect is None or effect["kind"] not in VELOCITY_KINDS:
    return 0.0
  j = effect["joint"] - 1
  slope = {"viscous": effect["value"],
           "coulomb": effect["value"] / COULOMB_VSCALE,
           "stribeck": effect["params"].get("F_s", 0) / COULOMB_VSCALE}
  q, qd = sample[0][::20].reshape(-1, model.n), sample[1][::20].reshape(
      -1, model.n)
  mass, _ = model.mass_bias(q, qd)
  minv_jj = np.linalg.inv(mass)[:, j, j].max()
  return slope[effect["kind"]] * float(minv_jj)


def draw_rate(rng, realism):
  """Sample rate (Hz): from RATES_HZ, or 50-100 Hz for a `real` low rate."""
  if realism and realism["low_rate"]:
    return float(rng.uniform(*LOW_RATE_HZ))
  return float(rng.choice(RATES_HZ))


def design_dynamic(rng, system, kind, realism=None):
  """Draws one dynamic case design (excitation, rate, effect, noise).

  frac is the final torque noise std as a fraction of each joint's torque
  range (after filtering and quantisation under `real`); effects are sized
  against it.
  """
  model = make_model(system)
  rate = draw_rate(rng, realism)
  period = 1.0 / rate
  if system == "panda":
    nb, total = int(rng.integers(3, 7)), float(rng.uniform(20, 30))
  else:
    nb, total = int(rng.integers(2, 6)), float(rng.uniform(20, 60))
  n_samples = int(total / nb * rate)
  excitation = str(rng.choice(EXCITATIONS))
  ref = make_reference(rng, system, excitation, nb, n_samples * period)
  t = np.arange(n_samples) * period
  q, qd, qdd = ref(t)
  tau = model.inverse(q, qd, qdd)
  sample = (q, qd, qdd, tau)
  trange = np.ptp(tau.reshape(-1, model.n), axis=0)
  effect = None
  frac = float(np.exp(rng.uniform(*np.log(NOISE_FRAC))))
  if kind in ("gain", "delay"):
    sized = size_system_wide(rng, kind, sample, period, trange)
    if sized is None:
      return None
    effect, frac = sized
  elif kind is not None:
    effect = size_per_joint(rng, kind, model, sample, frac * trange)
    if kind == "payload" and effect["value"] > (5.0 if system == "panda"
                                                else 2.0):
      return None
  lam = stiffness(model, effect, sample)
  n_sub = int(math.ceil(period / min(DT_MAX, 0.7 / lam if lam else DT_MAX)))
  return {"system": system, "model": model, "effect": effect, "ref": ref,
          "rate": rate, "nb": nb, "n_samples": n_samples, "frac": frac,
          "excitation": excitation, "n_sub": n_sub,
          "wn": 5.0 if kind == "delay" else 12.0, "realism": realism}


def simulate_real(rng, design, loop, delay):
  """Jittered sample times and the zero-order-hold simulation of a design.

  Returns (data dict, recorded times (n_samples, B)).
  """
  period = 1.0 / design["rate"]
  n_warm = int(round(WARMUP_S / period))
  jitter = design["realism"]["jitter_frac_of_period"]
  times = jittered_times(rng, design["n_samples"], design["nb"], period,
                         jitter, n_warm)
  data = simulate_zoh(loop, times, n_warm, design["n_sub"], delay, period)
  return data, times[n_warm:]


def zoh_lag(model, data, times, sigma):
  """What the hold looks like to a smoother, per joint: RMS / noise of
  M (q_dd just after the sample - central-difference q_dd) on clean data.

  The held torque acts like a delay of T/2 against a smoothed q_dd.
  """
  qdd = np.stack([np.gradient(data["qd"][:, b], times[:, b], axis=0)
                  for b in range(times.shape[1])], 1)
  q, qd = data["q"], data["qd"]
  diff = (model.inverse(q, qd, data["qdd"]) - model.inverse(q, qd, qdd))
  return rms(diff[2:-2].reshape(-1, model.n)) / sigma


def run_dynamic(rng, design):
  """Simulates a design; returns (noisy data, truth dict).

  noisy holds q, qd, tau (T, B, n) and t (T, B).
  """
  model, effect = design["model"], design["effect"]
  realism = design["realism"]
  period = 1.0 / design["rate"]
  ref = per_trajectory(design["ref"]) if realism else design["ref"]
  loop = ClosedLoop(model, effect, ref, design["wn"])
  delay = effect["value"] if effect and effect["kind"] == "delay" else 0.0
  if realism:
    data, times = simulate_real(rng, design, loop, delay)
  else:
    data = simulate(loop, period, design["n_sub"], design["n_samples"], delay)
    times = np.arange(design["n_samples"])[:, None] / design["rate"]
  n = model.n
  tau = data["tau"]
  sigma = design["frac"] * np.ptp(tau.reshape(-1, n), axis=0)
  resid = tau - model.inverse(data["q"], data["qd"], data["qdd"])
  per_joint = rms(resid.reshape(-1, n)) / sigma
  q_std = float(np.exp(rng.uniform(np.log(1e-5), np.log(1e-4))))
  qd_std = float(np.exp(rng.uniform(np.log(1e-3), np.log(1e-2))))
  if realism:
    noisy, diag = measure_real(rng, realism, design["rate"], times, data,
                               sigma / quant_factor(realism), q_std, qd_std)
  else:
    noisy = {"q": data["q"] + rng.normal(0, q_std, data["q"].shape),
             "qd": data["qd"] + rng.normal(0, qd_std, data["qd"].shape),
             "tau": tau + rng.normal(0, 1, tau.shape) * sigma}
  noisy["t"] = np.broadcast_to(times, tau.shape[:2])
  truth = {
      "system": design["system"], "control": effect is None, "static": False,
      "effects": [] if effect is None else [effect],
      "noise": {"tau_std": sigma.tolist(), "q_std": [q_std] * n,
                "qd_std": [qd_std] * n,
                "tau_std_fraction_of_range": design["frac"]},
      "sample_rate_hz": design["rate"], "excitation": design["excitation"],
      "n_trajectories": design["nb"],
      "duration_s": design["nb"] * design["n_samples"] * period,
      "effect_rms_to_noise": float(per_joint.max()) if effect else 0.0,
      "effect_rms_to_noise_per_joint": per_joint.tolist(),
      "integration": {"method": "rk4", "dt_s": period / design["n_sub"]},
      "controller": {"type": "computed-torque PD on the nominal model",
                     "wn_rad_s": design["wn"]},
  }
  if design["system"] == "pendulum" and effect and effect["kind"] in (
      "payload", "gain"):
    truth["equivalent"] = pendulum_equivalent(model, effect)
  if realism:
    lag = zoh_lag(model, data, times, sigma)
    truth["realism"] = dict(realism, **diag, tau_lowpass_std=(
        sigma / quant_factor(realism)).tolist(),
                            zoh_equivalent_delay_s=period / 2,
                            zoh_central_diff_rms_to_noise=lag.tolist())
    truth["controller"]["sampling"] = "zero-order hold at the sample instants"
    if realism["velocity"] == "backward_difference":
      truth["noise"]["qd_std"] = diag["qd_error_empirical_std"]
  return noisy, truth


def pendulum_equivalent(model, effect):
  """The equivalent gain of a pendulum payload or payload of a gain."""
  if effect["kind"] == "payload":
    return {"kind": "gain", "value": model.m / (model.m + effect["value"])}
  return {"kind": "payload", "value": model.m * (1 / effect["value"] - 1)}


def run_static(rng):
  """A Panda static-hold payload case: (data, truth)."""
  model = Panda()
  dm = float(rng.uniform(0.5, 3.0))
  plant = model.with_payload(dm)
  rate = float(rng.uniform(18.0, 22.0))
  n_pose = int(rng.integers(6, 13))
  lo, hi = PANDA_QMIN + 0.3, PANDA_QMAX - 0.3
  sigma = rng.uniform(0.05, 0.3, 7)
  q_std = float(np.exp(rng.uniform(np.log(1e-5), np.log(1e-4))))
  qd_std = float(np.exp(rng.uniform(np.log(1e-3), np.log(1e-2))))
  rows = []
  for pose in range(n_pose):
    qp = rng.uniform(lo, hi)
    n = int(rng.uniform(2.0, 5.0) * rate)
    q = np.tile(qp, (n, 1))
    zero = np.zeros_like(q)
    tau = plant.inverse(q, zero, zero)
    rows.append((pose, np.arange(n) / rate,
                 q + rng.normal(0, q_std, q.shape),
                 rng.normal(0, qd_std, q.shape),
                 tau + rng.normal(0, 1, tau.shape) * sigma))
  truth = {
      "system": "panda", "control": False, "static": True,
      "effects": [{"kind": "payload", "joint": 0, "value": dm,
                   "params": {"mass": dm}}],
      "noise": {"tau_std": sigma.tolist(), "q_std": [q_std] * 7,
                "qd_std": [qd_std] * 7},
      "sample_rate_hz": rate, "excitation": "static-hold",
      "n_trajectories": n_pose,
      "duration_s": float(sum(len(r[1]) for r in rows) / rate),
      "not_identifiable": list(VELOCITY_KINDS) + ["armature", "delay"],
      "note": ("static holds: velocity- and acceleration-dependent effects "
               "are not identifiable from these data"),
  }
  return rows, truth


def creep_hold(rng, realism, plant, qp, n, rate, noise):
  """One `real` static hold: (t, measured dict, creep velocity, diag).

  The pose was reached by a move that is not recorded; during the hold
  random joints creep at up to CREEP_MAX rad/s (quasi-static torque g(q)).
  noise is (sigma (7,), q_std, qd_std).
  """
  moving = rng.random(7) < 0.5
  creep = np.where(moving, rng.uniform(-CREEP_MAX, CREEP_MAX, 7), 0.0)
  times = jittered_times(rng, n, 1, 1.0 / rate,
                         realism["jitter_frac_of_period"])
  q = qp + times[..., None] * creep
  qd = np.broadcast_to(creep, q.shape).copy()
  tau = plant.inverse(q, qd, np.zeros_like(q))
  meas, diag = measure_real(rng, realism, rate, times,
                            {"q": q, "qd": qd, "tau": tau}, *noise)
  return times[:, 0], meas, creep, diag


def run_static_real(rng, realism):
  """A `real` Panda static-hold payload case: (rows, truth).

  As run_static, plus per-hold creep, jittered times, low-passed and
  quantised torque noise (0.05-0.3 N m before quantisation), encoder counts
  and, half the time, qd as a backward difference of the position.
  """
  dm = float(rng.uniform(0.5, 3.0))
  plant = Panda().with_payload(dm)
  rate = float(rng.uniform(18.0, 22.0))
  n_pose = int(rng.integers(6, 13))
  lo, hi = PANDA_QMIN + 0.3, PANDA_QMAX - 0.3
  sigma = rng.uniform(0.05, 0.3, 7)
  q_std = log_uniform(rng, 1e-5, 1e-4)
  qd_std = log_uniform(rng, 1e-3, 1e-2)
  rows, creeps, qd_err, n_total = [], [], [], 0
  for pose in range(n_pose):
    n = int(rng.uniform(2.0, 5.0) * rate)
    pose_q = rng.uniform(lo, hi)[None]
    t, meas, creep, diag = creep_hold(rng, realism, plant, pose_q, n, rate,
                                      (sigma, q_std, qd_std))
    rows.append((pose, t, meas["q"][:, 0], meas["qd"][:, 0],
                 meas["tau"][:, 0]))
    creeps.append(creep.tolist())
    qd_err.append(diag["qd_error_empirical_std"])
    n_total += n
  final = sigma * quant_factor(realism)
  truth = {
      "system": "panda", "control": False, "static": True,
      "effects": [{"kind": "payload", "joint": 0, "value": dm,
                   "params": {"mass": dm}}],
      "noise": {"tau_std": final.tolist(), "q_std": [q_std] * 7,
                "qd_std": [qd_std] * 7},
      "sample_rate_hz": rate, "excitation": "static-hold",
      "n_trajectories": n_pose, "duration_s": n_total / rate,
      "not_identifiable": list(VELOCITY_KINDS) + ["armature", "delay"],
      "note": ("static holds reached by unrecorded moves, with creep: "
               "velocity- and acceleration-dependent effects are not "
               "identifiable from these data"),
      "realism": dict(realism, tau_lowpass_std=sigma.tolist(),
                      tau_lowpass_cutoff_hz=realism[
                          "tau_lowpass_cutoff_frac_of_rate"] * rate,
                      creep_rad_s=creeps),
  }
  if realism["velocity"] == "backward_difference":
    truth["noise"]["qd_std"] = rms(np.array(qd_err)).tolist()
  return rows, truth


# ----------------------------------------------------------------------------
# Output.
# ----------------------------------------------------------------------------


def write_csv(path, n, rows):
  """Writes rows [(trajectory, t, q, qd, tau)] as a joint-space CSV."""
  header = (["t", "trajectory"] + [f"q{i}" for i in range(1, n + 1)] +
            [f"qd{i}" for i in range(1, n + 1)] +
            [f"tau{i}" for i in range(1, n + 1)])
  blocks = [np.column_stack((t, np.full(len(t), traj), q, qd, tau))
            for traj, t, q, qd, tau in rows]
  fmt = ["%.6f", "%d"] + ["%.10g"] * (3 * n)
  np.savetxt(path, np.vstack(blocks), delimiter=",", header=",".join(header),
             comments="", fmt=fmt)


def dynamic_rows(noisy):
  """Splits (T, B, n) arrays and t (T, B) into per-trajectory CSV rows."""
  return [(b, noisy["t"][:, b], noisy["q"][:, b], noisy["qd"][:, b],
           noisy["tau"][:, b]) for b in range(noisy["q"].shape[1])]


def assign(rng, n_cases, n_controls):
  """(system, kind or None) per dynamic case, systems and kinds balanced."""
  systems = [SYSTEMS[i % 3] for i in range(n_cases)]
  kinds = [KINDS[i % len(KINDS)] for i in range(n_cases - n_controls)]
  kinds = list(rng.permutation(kinds)) + [None] * n_controls
  order = rng.permutation(n_cases)
  return [(systems[i], kinds[order[i]]) for i in range(n_cases)]


def make_case(rng, system, kind, level):
  """(rows, truth) of one case at a realism level."""
  realism = (draw_realism(rng, kind == "static") if level == "real"
             else None)
  if kind == "static":
    return run_static_real(rng, realism) if realism else run_static(rng)
  design = None
  while design is None:
    design = design_dynamic(rng, system, kind, realism)
  noisy, truth = run_dynamic(rng, design)
  return dynamic_rows(noisy), truth


def generate(out, seed, n_cases, n_controls, n_static, level="ideal"):
  """Writes all cases and cases.json under out."""
  rng = np.random.Generator(np.random.PCG64(seed))
  os.makedirs(out, exist_ok=True)
  listing = []
  plan = assign(rng, n_cases, n_controls) + [("panda", "static")] * n_static
  for idx, (system, kind) in enumerate(plan):
    name = f"case_{idx:03d}"
    start = time.time()
    rows, truth = make_case(rng, system, kind, level)
    truth.update({"name": name, "seed": seed})
    folder = os.path.join(out, name)
    os.makedirs(folder, exist_ok=True)
    write_csv(os.path.join(folder, "measured.csv"), make_model(system).n, rows)
    with open(os.path.join(folder, "truth.json"), "w") as f:
      json.dump(truth, f, indent=1)
    listing.append({"name": name, "system": system,
                    "kinds": [e["kind"] for e in truth["effects"]],
                    "control": truth["control"], "static": truth["static"]})
    print(f"{name} {system:8s} {kind or 'control':9s} "
          f"ratio={truth.get('effect_rms_to_noise', float('nan')):.1f} "
          f"{time.time() - start:.1f}s", file=sys.stderr, flush=True)
  summary = {"seed": seed, "cases": listing}
  if level != "ideal":
    summary["realism"] = level
  with open(os.path.join(out, "cases.json"), "w") as f:
    json.dump(summary, f, indent=1)


# ----------------------------------------------------------------------------
# Panda self-checks (--check).
# ----------------------------------------------------------------------------


def panda_frames(q, flange=True):
  """Base-frame 4x4 transforms of frames 1..7 (and the flange)."""
  rows = list(zip(PANDA_DH, q)) + ([((0.0, PANDA_FLANGE_D, 0.0), 0.0)]
                                   if flange else [])
  frames, pose = [], np.eye(4)
  for (a, d, al), th in rows:
    c, s, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
    pose = pose @ np.array([[c, -s, 0, a], [s * ca, c * ca, -sa, -sa * d],
                            [s * sa, c * sa, ca, ca * d], [0, 0, 0, 1]])
    frames.append(pose)
  return frames


def panda_energy(model, q, qd):
  """Kinetic + potential energy of a Panda model (unbatched)."""
  mass, _ = model.mass_bias(q[None], np.zeros((1, 7)))
  frames = panda_frames(q, flange=False)
  pot = sum(model.mass[i] * G_PANDA * (frames[i][:3, :3] @ model.com[i] +
                                       frames[i][:3, 3])[2] for i in range(7))
  return 0.5 * qd @ mass[0] @ qd + pot


def check_panda():
  """Prints the Panda checks against panda_parameters.md and physics."""
  ready = np.array([0, -np.pi / 4, 0, -3 * np.pi / 4, 0, np.pi / 2, np.pi / 4])
  q_test = np.array([0, 0, 0, -np.pi / 2, 0, np.pi / 2, np.pi / 4])
  fk_ref = ((np.zeros(7), (0.088, 0, 0.926)), (ready, (0.3069, 0, 0.5903)),
            (q_test, (0.5545, 0, 0.6245)))
  for q, p in fk_ref:
    got = panda_frames(q)[-1][:3, 3]
    print(f"FK flange {np.round(got, 4)} sheet {p} "
          f"err {np.abs(got - p).max():.1e}")
  g_ref = ((q_test, (0, -25.256618, 0, 18.567248, 0.633630, 1.693106, 0)),
           (np.zeros(7), (0, -3.433259, 0, -3.256112, 0, 1.693638, 0)),
           (ready, (0, -1.770771, -0.643780, 18.567248, 0.633630, 1.693106,
                    0)))
  model = Panda()
  zero = np.zeros((1, 7))
  for q, g in g_ref:
    got = model.inverse(q[None], zero, zero)[0]
    print(f"g(q) max err vs sheet {np.abs(got - g).max():.1e}")
  qd = np.array([0.5, -0.4, 0.3, -0.2, 0.6, -0.5, 0.7])
  qdd = np.array([1, -1, 0.5, -0.5, 1, -1, 0.5])
  tau_ref = (1.495331, -27.698952, 1.457273, 19.193155, 0.708798, 1.653629,
             -0.007766)
  got = model.inverse(q_test[None], qd[None], qdd[None])[0]
  print(f"ID(q_test) max err vs sheet {np.abs(got - tau_ref).max():.1e}")
  m_row1 = (1.178108, -0.036057, 1.140771, 0.001574, 0.036181, 0.001664,
            -0.009169)
  mass, _ = model.mass_bias(q_test[None], zero)
  print(f"M(q_test) row 1 max err {np.abs(mass[0, 0] - m_row1).max():.1e}, "
        f"M77 {mass[0, 6, 6]:.6f} (sheet 0.004910)")
  check_mass_and_energy()


def check_mass_and_energy():
  """M symmetric positive definite; energy conserved in free motion; the
  payload's gravity torque equals the gradient of its potential energy."""
  rng = np.random.Generator(np.random.PCG64(0))
  qs = rng.uniform(PANDA_QMIN, PANDA_QMAX, (200, 7))
  for model in (Panda(), Panda(2.0)):
    mass, _ = model.mass_bias(qs, np.zeros_like(qs))
    asym = np.abs(mass - mass.transpose(0, 2, 1)).max()
    print(f"payload {model.payload} kg: max |M - M^T| {asym:.1e}, "
          f"min eig {np.linalg.eigvalsh(mass).min():.2e} over 200 poses")
    q = rng.uniform(PANDA_QMIN, PANDA_QMAX)[None]
    qd = rng.uniform(-1, 1, (1, 7))
    e0 = panda_energy(model, q[0], qd[0])
    dt, energies = 2e-4, []
    for _ in range(5000):   # 1 s free motion, RK4
      def f(qq, vv):
        m, h = model.mass_bias(qq, vv)
        return np.linalg.solve(m, -h[..., None])[..., 0]
      k1 = f(q, qd)
      k2 = f(q + dt / 2 * qd, qd + dt / 2 * k1)
      k3 = f(q + dt / 2 * (qd + dt / 2 * k1), qd + dt / 2 * k2)
      k4 = f(q + dt * (qd + dt / 2 * k2), qd + dt * k3)
      q = q + dt * (qd + dt / 6 * (k1 + k2 + k3))
      qd = qd + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
      energies.append(panda_energy(model, q[0], qd[0]))
    print(f"payload {model.payload} kg: energy drift over 1 s free motion "
          f"{np.max(np.abs(np.array(energies) - e0)):.1e} J (E0 {e0:.3f} J)")
  q = rng.uniform(PANDA_QMIN, PANDA_QMAX)
  zero = np.zeros((1, 7))
  g_pay = (Panda(1.0).inverse(q[None], zero, zero) -
           Panda().inverse(q[None], zero, zero))[0]

  def pot(qq):
    return G_PANDA * panda_frames(qq)[-1][2, 3]   # 1 kg at the flange
  grad = np.array([(pot(q + 1e-6 * e) - pot(q - 1e-6 * e)) / 2e-6
                   for e in np.eye(7)])
  print(f"1 kg flange payload: RNEA gravity vs dU/dq max err "
        f"{np.abs(g_pay - grad).max():.1e}")


def main():
  """Command line."""
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--out")
  parser.add_argument("--seed", type=int, default=0)
  parser.add_argument("--cases", type=int, default=40)
  parser.add_argument("--controls", type=int, default=10)
  parser.add_argument("--static", type=int, default=4)
  parser.add_argument("--realism", choices=REALISM_LEVELS, default="ideal",
                      help="ideal: white noise, exact samples (default); "
                      "real: zero-order hold, filtered and quantised "
                      "sensors, jitter, creeping static holds")
  parser.add_argument("--check", action="store_true",
                      help="run the Panda dynamics checks and exit")
  args = parser.parse_args()
  if args.check:
    check_panda()
    return
  if not args.out or not 0 <= args.controls <= args.cases or args.static < 0:
    parser.error("need --out, 0 <= --controls <= --cases, --static >= 0")
  generate(args.out, args.seed, args.cases, args.controls, args.static,
           args.realism)


if __name__ == "__main__":
  main()
