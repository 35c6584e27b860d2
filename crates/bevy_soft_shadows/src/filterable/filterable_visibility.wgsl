#define_import_path bevy_soft_shadows::filterable_visibility

// Visibility from a filtered shadow-map texel (Gumbau 2011, ch. 7): what share of the occluders
// the filter saw lies behind a receiver at depth zr (light space, [0, 1], larger farther from
// the light). `bevy_soft_shadows::filterable::visibility` is the CPU reference of each.

// Variance shadow maps: the one-tailed Chebyshev bound over m = (E[z], E[z²]).
fn chebyshev(m: vec2<f32>, zr: f32, min_variance: f32) -> f32 {
    let mean = m.x;
    if zr <= mean {
        return 1.0;
    }
    let variance = max(m.y - mean * mean, min_variance);
    let d = zr - mean;
    return clamp(variance / (variance + d * d), 0.0, 1.0);
}

// Exponential shadow maps: E[e^{c·zo}] · e^{−c·zr}.
fn exponential(moment: f32, zr: f32, c: f32) -> f32 {
    return clamp(moment * exp(-c * zr), 0.0, 1.0);
}

// erf by the closed form the thesis uses (a ≈ 0.140012).
fn erf_approx(x: f32) -> f32 {
    let a = 0.140012;
    let x2 = x * x;
    let inner = -x2 * (4.0 / 3.14159265 + a * x2) / (1.0 + a * x2);
    let magnitude = sqrt(max(1.0 - exp(inner), 0.0));
    return select(magnitude, -magnitude, x < 0.0);
}

// Eq. 7.4: a normal distribution of the two moments, biased by eq. 7.1–7.2 (lit in front of
// the mean).
fn gaussian_cdf(m: vec2<f32>, zr: f32, min_variance: f32) -> f32 {
    let mean = m.x;
    if zr <= mean {
        return 1.0;
    }
    let sigma = sqrt(max(m.y - mean * mean, min_variance));
    return clamp(1.0 - erf_approx((zr - mean) / (sigma * 1.41421356)), 0.0, 1.0);
}

// Eq. 7.6–7.7: a power law over the texel's range s = (mean, min, max) with the filtered mean.
fn power_cdf(s: vec3<f32>, zr: f32) -> f32 {
    let lo = s.y;
    let hi = s.z;
    let range = hi - lo;
    if !(range > 1e-6) {
        return select(0.0, 1.0, zr <= hi);
    }
    let mean = clamp(s.x, lo, hi);
    if zr >= hi {
        return 0.0;
    }
    let t = max((zr - lo) / range, 0.0);
    let beta = max((mean - lo) / max(hi - mean, 1e-6), 1e-6);
    let t_mean = beta / (beta + 1.0);
    if t <= t_mean {
        return 1.0;
    }
    let at_mean = 1.0 - pow(t_mean, beta);
    return clamp((1.0 - pow(t, beta)) / max(at_mean, 1e-6), 0.0, 1.0);
}

// Four-moment shadow maps, Hamburger variant (Peters and Klein 2015, algorithm 3), in f32.
fn hamburger_msm(moments: vec4<f32>, zr: f32, moment_bias: f32) -> f32 {
    let b = mix(moments, vec4(0.5), moment_bias);
    let z0 = zr;
    let l32_d22 = -b.x * b.y + b.z;
    let d22 = -b.x * b.x + b.y;
    let squared_depth_variance = -b.y * b.y + b.w;
    let d33_d22 = squared_depth_variance * d22 - l32_d22 * l32_d22;
    if !(d22 > 0.0 && d33_d22 > 0.0) {
        return select(0.0, 1.0, zr <= b.x + 1e-6);
    }
    let inv_d22 = 1.0 / d22;
    let l32 = l32_d22 * inv_d22;
    var c = vec3(1.0, z0, z0 * z0);
    c.y -= b.x;
    c.z -= b.y + l32 * c.y;
    c.y *= inv_d22;
    c.z *= d22 / d33_d22;
    c.y -= l32 * c.z;
    c.x -= c.y * b.x + c.z * b.y;
    let p = c.y / c.z;
    let q = c.x / c.z;
    let r = sqrt(max(p * p * 0.25 - q, 0.0));
    let z1 = -p * 0.5 - r;
    let z2 = -p * 0.5 + r;
    var switch_ = vec4(0.0);
    if z2 < z0 {
        switch_ = vec4(z1, z0, 1.0, 1.0);
    } else if z1 < z0 {
        switch_ = vec4(z0, z1, 0.0, 1.0);
    }
    let quotient = (switch_.x * z2 - b.x * (switch_.x + z2) + b.y) / ((z2 - switch_.y) * (z0 - z1));
    let shadow = clamp(switch_.z + switch_.w * quotient, 0.0, 1.0);
    return 1.0 - shadow;
}
