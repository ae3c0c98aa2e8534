"""The same pixel model as the C++ engine, written as plain vectorised NumPy.

Two uses: the speed baseline of bench/bench_engine.py (what a careful NumPy simulator of
this model costs), and an independent implementation that the tests compare the engine
with (identical events with noise off; equal statistics with noise on). Randomness comes
from numpy.random.Generator, so noisy runs agree in distribution, not bit for bit.

Vectorised over pixels at each sample; the comparator handles several events per pixel
and interval by repeating its step for the pixels that still have something to do.
"""

from __future__ import annotations

import math

import numpy as np

from evstwin import EVENT_DTYPE, PixelParams
from evstwin._core import ELEMENTARY_CHARGE_C as E


class NumpySensor:
    def __init__(self, width: int, height: int, params: PixelParams, seed: int = 0) -> None:
        self.w, self.h, self.p = width, height, params
        self.n = width * height
        self.rng = np.random.default_rng(seed)
        p = params
        self.e_per_photon = p.electrons_per_photon
        self.dark = 0.0 if p.dark_model == "none" else p.dark_rate_e_per_s
        self.th_on = np.full(self.n, p.theta_on)
        self.th_off = np.full(self.n, p.theta_off)
        if p.threshold_sigma > 0:
            for th in (self.th_on, self.th_off):
                z = self.rng.standard_normal(self.n)
                bad = 1 + p.threshold_sigma * z < 0.01
                while bad.any():
                    z[bad] = self.rng.standard_normal(int(bad.sum()))
                    bad = 1 + p.threshold_sigma * z < 0.01
                th *= 1 + p.threshold_sigma * z
        self.started = False
        self.t_last = -math.inf

    def run(self, photon_rate: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        rate = np.asarray(photon_rate, dtype=np.float64).reshape(len(t_s), self.n)
        chunks: list[np.ndarray] = []
        for k in range(len(t_s)):
            if not self.started:
                self.x = np.log(E * (self.e_per_photon * rate[k] + self.dark))
                self.z = self.x.copy()
                self.y = self.x.copy()
                self.ref = self.x.copy()
                self.refr_until = np.full(self.n, -np.inf)
                self.started = True
            else:
                chunks.append(self._step(rate[k], self.t_last, float(t_s[k])))
            self.t_last = float(t_s[k])
        events = np.concatenate(chunks) if chunks else np.zeros(0, EVENT_DTYPE)
        return events

    def _current(self, lam: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(current [A], x = ln of what the log photoreceptor sees): counts N enter the log
        as N + 1/2, as in the engine."""
        p, rng = self.p, self.rng
        signal = self.e_per_photon * lam
        if p.photon_shot_noise and p.dark_model != "paper":
            n = rng.poisson((signal + self.dark) * dt).astype(np.float64)
            return n * (E / dt), np.log(n + 0.5) + math.log(E / dt)
        flow = np.zeros(self.n) if p.photon_shot_noise else signal.copy()
        seen = flow.copy()
        if p.photon_shot_noise:
            n = rng.poisson(signal * dt).astype(np.float64)
            flow += n * (1.0 / dt)
            seen += (n + 0.5) * (1.0 / dt)
        if p.dark_model == "poisson":
            n = rng.poisson(np.full(self.n, self.dark * dt)).astype(np.float64)
            flow += n * (1.0 / dt)
            seen += (n + 0.5) * (1.0 / dt)
        elif p.dark_model == "paper":
            n = rng.poisson(np.full(self.n, self.dark)).astype(np.float64)
            flow += n
            seen += n
        return E * flow, np.log(E * seen)

    def _step(self, lam: np.ndarray, t0: float, t1: float) -> np.ndarray:
        p = self.p
        dt = t1 - t0
        current, x = self._current(lam, dt)
        z = x
        if p.pr_pole:
            u = 2 * math.pi * p.pr_cutoff_ref_hz * (current / p.pr_ref_current_a) * dt
            ramp = np.where(u > 1e-12, -np.expm1(-u) / np.maximum(u, 1e-300), 1.0)
            z = x + (self.z - self.x) * np.exp(-u) - (x - self.x) * ramp
        if p.cutoff_hz is None:
            y = z
        else:
            u = 2 * math.pi * p.cutoff_hz * dt
            if p.lowpass == "euler":
                y = u * self.z + (1 - u) * self.y
            else:
                y = z + (self.y - self.z) * math.exp(-u) - (z - self.z) * (-math.expm1(-u) / u)

        # Shot noise, eq. 12-15.
        noise_pol = np.full(self.n, -1, dtype=np.int8)
        t_noise = np.zeros(self.n)
        if p.shot_noise_rate_hz > 0:
            ratio = np.minimum(current / p.shot_noise_i_max_a, 1.0)
            prob = ((p.shot_noise_factor - 1) * ratio + 1) * p.shot_noise_rate_hz * dt
            u = self.rng.random(self.n)
            off, on = u < prob, u > 1 - prob
            noise_pol[off], noise_pol[on] = 0, 1
            t_noise[off] = t0 + dt * (u[off] / prob[off])
            t_noise[on] = t0 + dt * ((1 - u[on]) / prob[on])

        events = self._compare(y, t0, t1, dt, noise_pol, t_noise)
        self.x, self.z, self.y = x, z, y
        return events

    def _compare(self, y1, t0, t1, dt, noise_pol, t_noise) -> np.ndarray:
        p = self.p
        th_on, th_off = self.th_on, self.th_off
        g = (y1 - self.y) * (1.0 / dt) + p.leak_rate_hz * th_on
        db = self.y - self.ref
        d1 = db + g * dt
        quiet = (noise_pol < 0) & (self.refr_until <= t0) & (db < th_on) & (db > -th_off) & (d1 < th_on) & (d1 > -th_off)
        self.ref = np.where(quiet, y1 - d1, self.ref)
        idx = np.flatnonzero(~quiet)
        tb = np.full(idx.size, t0)
        db = db[idx]
        g_, on_, off_ = g[idx], th_on[idx], th_off[idx]
        npol, tn = noise_pol[idx].copy(), t_noise[idx]
        refr = self.refr_until[idx].copy()
        out_t: list[np.ndarray] = []
        out_px: list[np.ndarray] = []
        out_p: list[np.ndarray] = []
        active = np.ones(idx.size, bool)

        def emit(mask: np.ndarray, times: np.ndarray, pol) -> None:
            out_t.append(times[mask])
            out_px.append(idx[mask])
            out_p.append(np.broadcast_to(np.asarray(pol, np.uint8), mask.shape)[mask].astype(np.uint8))

        while active.any():
            # 1. Refractory: noise inside it is lost; wake up at its end or stop.
            dead = active & (refr > tb)
            npol[dead & (npol >= 0) & (tn < refr)] = -1
            stop = dead & (refr >= t1)
            active &= ~stop
            wake = dead & ~stop
            db[wake] += g_[wake] * (refr[wake] - tb[wake])
            tb[wake] = refr[wake]
            # 2. Already past a threshold: fire now, merge the levels.
            fire_on = active & (db >= on_)
            fire_off = active & ~fire_on & (db <= -off_)
            emit(fire_on, tb, 1)
            emit(fire_off, tb, 0)
            db[fire_on] -= np.floor(db[fire_on] / on_[fire_on]) * on_[fire_on]
            db[fire_off] += np.floor(-db[fire_off] / off_[fire_off]) * off_[fire_off]
            fired = fire_on | fire_off
            refr[fired] = tb[fired] + p.refractory_s
            # 3. The next crossing on the line, or the noise pulse if it comes first.
            step = active & ~fired
            with np.errstate(divide="ignore", invalid="ignore"):
                tc = np.where(g_ > 0, tb + (on_ - db) / g_, np.where(g_ < 0, tb + (-off_ - db) / g_, np.inf))
            pol = np.where(g_ > 0, 1, 0)
            noise_first = step & (npol >= 0) & (tn < tc)
            db[noise_first] += g_[noise_first] * (tn[noise_first] - tb[noise_first])
            tb[noise_first] = tn[noise_first]
            emit(noise_first, tb, npol)
            npol[noise_first] = -1
            db[noise_first] = 0.0
            refr[noise_first] = tb[noise_first] + p.refractory_s
            rest = step & ~noise_first
            done = rest & (tc > t1)
            active &= ~done
            cross = rest & ~done
            emit(cross, tc, pol)
            tb[cross] = tc[cross]
            db[cross] = 0.0
            refr[cross] = tb[cross] + p.refractory_s

        self.ref[idx] = y1[idx] - (db + g_ * (t1 - tb))
        self.refr_until[idx] = refr
        ev = np.zeros(sum(a.size for a in out_t), EVENT_DTYPE)
        if ev.size:
            t = np.floor(np.concatenate(out_t) * 1e6 + 1e-3).astype(np.int64)  # as Sensor::floor_us
            px = np.concatenate(out_px)
            order = np.lexsort((px, t))
            ev["t"], ev["x"], ev["y"], ev["p"] = t[order], (px % self.w)[order], (px // self.w)[order], np.concatenate(out_p)[order]
        return ev


def reference_events(width: int, height: int, params: PixelParams, photon_rate, t_s, seed: int | None = 0) -> np.ndarray:
    return NumpySensor(width, height, params, seed or 0).run(photon_rate, np.asarray(t_s, float))
