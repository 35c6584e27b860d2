// Trees lit as volumes of leaves (Boulanger 2008, §5.2–5.4), per leaf vertex: the light a leaf
// sends to the eye from the sky and the ground through the crown (eq. 5.6), from the sun through
// the crown (eq. 5.8) and from one bounce of sunlight off its neighbours (eq. 5.11 with 5.24), by
// the two-sided leaf BSDF of eq. 5.4. `bevy_foliage::lighting::model` is the CPU reference,
// function for function; every direction is in the tree's model space, pointing away from the
// leaf.
#define_import_path bevy_foliage::tree_lighting

// ξ = √3/3: the eight sampling directions are (±ξ, ±ξ, ±ξ), bit 0 of j meaning +x, bit 1 +y,
// bit 2 +z (`lighting::bins::DIRECTIONS`).
const XI: f32 = 0.57735026;
const PI: f32 = 3.14159265;
// The least light a stored attenuation holds (`lighting::bins::DARKEST_LIGHT`).
const DARKEST_LIGHT: f32 = 1.52590219e-5;
// The largest seen-part gain (`lighting::seen_part::GAIN_RANGE`).
const COVERED_GAIN_MAX: f32 = 4.0;

// The leaf's reflectances and transmittances per channel (`model::LeafMaterial`).
struct LeafOptics {
    reflectance_front: vec3<f32>,
    reflectance_back: vec3<f32>,
    transmittance_front: vec3<f32>,
    transmittance_back: vec3<f32>,
}

// What lights the tree: the sun (towards it, and its irradiance; zero irradiance for no sun),
// the sky's radiance over the upper hemisphere and the ground's under it.
struct TreeLights {
    to_sun: vec3<f32>,
    sun: vec3<f32>,
    sky: vec3<f32>,
    ground: vec3<f32>,
}

// What the CPU hands the tree lighting (`pruning::material::TreeLightUniform`): the leaves'
// optics as multiples of their colour, the world direction towards the sun, the sun's
// irradiance, the sky's and the ground's radiance (rgb).
struct TreeLightUniform {
    reflectance_front: vec4<f32>,
    reflectance_back: vec4<f32>,
    transmittance_front: vec4<f32>,
    transmittance_back: vec4<f32>,
    to_sun: vec4<f32>,
    sun: vec4<f32>,
    sky: vec4<f32>,
    ground: vec4<f32>,
}

// The optics of a leaf of colour `albedo`.
fn optics_of(u: TreeLightUniform, albedo: vec3<f32>) -> LeafOptics {
    return LeafOptics(
        u.reflectance_front.rgb * albedo,
        u.reflectance_back.rgb * albedo,
        u.transmittance_front.rgb * albedo,
        u.transmittance_back.rgb * albedo,
    );
}

// The scene's lights with the direction towards the sun given in the tree's frame.
fn lights_of(u: TreeLightUniform, to_sun: vec3<f32>) -> TreeLights {
    return TreeLights(to_sun, u.sun.rgb, u.sky.rgb, u.ground.rgb);
}

// A leaf's light split by where it comes from: the sky and the ground; the sun's direct light
// were nothing in its way (eq. 5.8 without the crown's share), and the share the crown lets
// through; one bounce of sunlight. The leaf's light is `sky + sun * through + bounce`.
struct LeafLight {
    sky: vec3<f32>,
    sun: vec3<f32>,
    through: f32,
    bounce: vec3<f32>,
    // The leaf's open share of the sphere (`model::open_share`), for the bounce's seen-part gain.
    open: f32,
}

fn direction(j: u32) -> vec3<f32> {
    return vec3(
        select(-XI, XI, (j & 1u) != 0u),
        select(-XI, XI, (j & 2u) != 0u),
        select(-XI, XI, (j & 4u) != 0u),
    );
}

// Eq. 5.4, cosine included (`model::bsdf`); `seen_front`: the eye is on the normal's side.
fn bsdf(optics: LeafOptics, n: vec3<f32>, seen_front: bool, w: vec3<f32>) -> vec3<f32> {
    let c = dot(n, w);
    let lit_front = max(c, 0.0);
    let lit_back = max(-c, 0.0);
    if seen_front {
        return (optics.reflectance_front * lit_front + optics.transmittance_back * lit_back) / PI;
    }
    return (optics.transmittance_front * lit_front + optics.reflectance_back * lit_back) / PI;
}

// `model::octant_cosine`: ∫ max(m · ω, 0) dω over bin j's octant — its spherical triangle
// clipped to m's side of the plane, by Lambert's polygon formula.
fn octant_cosine(m: vec3<f32>, j: u32) -> f32 {
    let d = direction(j);
    var corners = array<vec3<f32>, 3>(
        vec3(sign(d.x), 0.0, 0.0), vec3(0.0, sign(d.y), 0.0), vec3(0.0, 0.0, sign(d.z)));
    var clipped: array<vec3<f32>, 4>;
    var count = 0u;
    for (var k = 0u; k < 3u; k += 1u) {
        let a = corners[k];
        let b = corners[(k + 1u) % 3u];
        let da = dot(m, a);
        let db = dot(m, b);
        if da >= 0.0 {
            clipped[count] = a;
            count += 1u;
        }
        if (da >= 0.0) != (db >= 0.0) {
            let c = a + (b - a) * (da / (da - db));
            clipped[count] = select(vec3(0.0), normalize(c), length(c) > 0.0);
            count += 1u;
        }
    }
    if count < 3u {
        return 0.0;
    }
    var sum = 0.0;
    for (var k = 0u; k < count; k += 1u) {
        let a = clipped[k];
        let b = clipped[(k + 1u) % count];
        let normal = cross(a, b);
        let len = length(normal);
        if len > 1e-9 {
            sum += acos(clamp(dot(a, b), -1.0, 1.0)) * dot(m, normal / len);
        }
    }
    return abs(0.5 * sum);
}

// `model::one_minus_exp_over`: (1 − e^(−g·s)) / g, and its limit s as g goes to 0.
fn one_minus_exp_over(g: f32, s: f32) -> f32 {
    let x = g * s;
    if abs(x) < 1e-4 {
        return s * (1.0 - 0.5 * x);
    }
    return (1.0 - exp(-x)) / g;
}

// Eight gains of the octants blended towards the eye `to_eye` by their cosine lobes (eq. 5.7's
// weights; `lighting::seen_part::seen_gain`).
fn seen_gain(gains: array<f32, 8>, to_eye: vec3<f32>) -> f32 {
    var sum = 0.0;
    var blended = 0.0;
    for (var j = 0u; j < 8u; j += 1u) {
        let lobe = max(dot(to_eye, direction(j)), 0.0);
        sum += lobe;
        blended += lobe * gains[j];
    }
    return select(1.0, blended / sum, sum > 0.0);
}

// Byte `i` of a leaf's open map as stored (`leaf_pulling::leaf_open_map`).
fn open_map_byte(map: vec4<u32>, i: u32) -> u32 {
    return (map[i / 4u] >> (8u * (i % 4u))) & 0xffu;
}

// Whether a stored open map holds cells (all 0: no map; `LeafOpenMap::is_map`).
fn has_open_map(map: vec4<u32>) -> bool {
    return map.x != 0u || map.y != 0u || (map.z & 0xffu) != 0u;
}

// A unit vector stored octahedrally in two bytes (`lighting::open_map::decode_axis`).
fn open_map_axis(lo: u32, hi: u32) -> vec3<f32> {
    var xy = vec2(f32(lo), f32(hi)) / 255.0 * 2.0 - 1.0;
    let z = 1.0 - abs(xy.x) - abs(xy.y);
    if z < 0.0 {
        let s = select(vec2(-1.0), vec2(1.0), xy >= vec2(0.0));
        xy = (1.0 - abs(xy.yx)) * s;
    }
    let v = vec3(xy, z);
    return select(vec3(1.0, 0.0, 0.0), normalize(v), dot(v, v) > 0.0);
}

// Where a leaf vertex lies on its open map's grid: its offset from the leaf's centroid along
// the grid's two axes, in units of the leaf's radius (−1 to 1 across the square). Linear in
// the offset, so the rasteriser carries it to each pixel exactly.
fn open_map_at(map: vec4<u32>, offset: vec3<f32>, radius: f32) -> vec2<f32> {
    let r = max(radius, 1e-6);
    return vec2(
        dot(offset, open_map_axis(open_map_byte(map, 9u), open_map_byte(map, 10u))),
        dot(offset, open_map_axis(open_map_byte(map, 11u), open_map_byte(map, 12u)))) / r;
}

// The gain of the open map's cell at `at` on its grid (`open_map_at`): the cell's open share
// over the leaf's mean, its base-2 logarithm stored over [−2, 2] in 254 steps, codes 1–255
// (`lighting::open_map::StoredOpenMap::gain_at`); 1 without a map.
fn open_map_gain(map: vec4<u32>, at: vec2<f32>) -> f32 {
    if !has_open_map(map) {
        return 1.0;
    }
    let cell = clamp(floor((at + 1.0) * 0.5 * 3.0), vec2(0.0), vec2(2.0));
    let q = open_map_byte(map, u32(cell.y) * 3u + u32(cell.x));
    return select(1.0, exp2(f32(q - 1u) / 254.0 * 4.0 - 2.0), q != 0u);
}

// The seen-part gain of the part of the sphere the neighbours cover, where the bounce comes
// from, for the sky's gain `gain` and the leaf's open share `open`
// (`lighting::seen_part::covered_gain`).
fn covered_gain(gain: f32, open: f32) -> f32 {
    if open >= 1.0 - 1e-4 {
        return 1.0;
    }
    let o = max(open, 0.0);
    return clamp((1.0 - gain * o) / (1.0 - o), 0.0, COVERED_GAIN_MAX);
}

// Sun direction `k` of the bounce ratios' basis (`lighting::gathered_bounce::SUN_BASIS`): the
// eight sampling directions, then +x, −x, +y, −y, +z, −z.
fn sun_basis(k: u32) -> vec3<f32> {
    if k < 8u {
        return direction(k);
    }
    let axis = (k - 8u) / 2u;
    let s = select(1.0, -1.0, (k % 2u) == 1u);
    return vec3(select(0.0, s, axis == 0u), select(0.0, s, axis == 1u), select(0.0, s, axis == 2u));
}

// A leaf's bounce ratios (front face's fourteen, then the back's) for the sun towards
// `to_sun`, blended by the basis directions' cosine lobes to the fourth, normalised
// (`lighting::gathered_bounce::ratio_towards`): the factors on eq. 5.24's bins on the leaf's
// front and back faces.
fn ratio_towards(ratios: array<f32, 28>, to_sun: vec3<f32>) -> vec2<f32> {
    var sum = 0.0;
    var blended = vec2(0.0);
    for (var k = 0u; k < 14u; k += 1u) {
        let c = max(dot(to_sun, sun_basis(k)), 0.0);
        let c2 = c * c;
        let w = c2 * c2;
        sum += w;
        blended += w * vec2(ratios[k], ratios[14u + k]);
    }
    if sum > 0.0 {
        return blended / sum;
    }
    var mean = vec2(0.0);
    for (var k = 0u; k < 14u; k += 1u) {
        mean += vec2(ratios[k], ratios[14u + k]);
    }
    return mean / 14.0;
}

// Suns on a ring of re-gathered ratios (`lighting::bounce_ring::RING_NODES`), and the degrees of
// elevation from its ring within which a sun takes the ring alone and beyond which the bake's
// blend alone (`RING_FULL_DEGREES`, `RING_GONE_DEGREES`).
const RING_NODES: u32 = 14u;
const RING_FULL_DEGREES: f32 = 2.0;
const RING_GONE_DEGREES: f32 = 6.0;

// How much of a leaf's ratios its type's ring at sun height `ring_height` gives for the sun
// towards `to_sun` (`lighting::bounce_ring::ring_weight`): 1 within RING_FULL_DEGREES of the
// ring's elevation, 0 beyond RING_GONE_DEGREES (and for no ring, a height outside [−1, 1]),
// smoothstep between.
fn ring_weight(ring_height: f32, to_sun: vec3<f32>) -> f32 {
    if !(abs(ring_height) <= 1.0) {
        return 0.0;
    }
    let apart = abs(asin(clamp(to_sun.y, -1.0, 1.0)) - asin(ring_height)) * (180.0 / PI);
    let t = clamp((apart - RING_FULL_DEGREES) / (RING_GONE_DEGREES - RING_FULL_DEGREES), 0.0, 1.0);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

// Where the azimuth of `to_sun` falls on the ring (node k at azimuth 2πk/14 from +x towards
// +z): the nodes either side and how far from the first towards the second it lies
// (`lighting::gathered_bounce::nodes_either_side`).
struct RingSpan {
    i: u32,
    j: u32,
    f: f32,
}

fn ring_span(to_sun: vec3<f32>) -> RingSpan {
    let step = 2.0 * PI / f32(RING_NODES);
    var x = atan2(to_sun.z, to_sun.x) / step;
    x = x - f32(RING_NODES) * floor(x / f32(RING_NODES));
    let i = min(u32(floor(x)), RING_NODES - 1u);
    return RingSpan(i, (i + 1u) % RING_NODES, clamp(x - f32(i), 0.0, 1.0));
}

// The ratios towards `to_sun` from a leaf's ring (node k's front face at k, its back face at
// 14 + k): linear in azimuth between the nodes either side
// (`lighting::bounce_ring::ratio_on_ring`).
fn ratio_on_ring(ring: array<f32, 28>, to_sun: vec3<f32>) -> vec2<f32> {
    let at = ring_span(to_sun);
    let a = vec2(ring[at.i], ring[RING_NODES + at.i]);
    let b = vec2(ring[at.j], ring[RING_NODES + at.j]);
    return a + at.f * (b - a);
}

// What the fragment needs of the leaf's sunlit shares on its type's ring to draw the sun where
// the shadow map does not resolve leaves (`through_on_ring`): the share read on the ring,
// linear in azimuth, from the leaf's shares at this vertex (`leaf_ring_shares`, linear across
// the leaf, so the rasteriser carries it to each fragment exactly), the seen-part gain `gain`,
// the crown's hotspot exponent `exponent` and the ring's weight (`ring_weight`; 0: the blend
// alone).
fn ring_sun_at(
    ring_height: f32,
    shares: array<f32, 14>,
    gain: f32,
    exponent: f32,
    to_sun: vec3<f32>,
) -> vec4<f32> {
    let w = ring_weight(ring_height, to_sun);
    if w <= 0.0 {
        return vec4(0.0, 1.0, 1.0, 0.0);
    }
    let at = ring_span(to_sun);
    let share = shares[at.i] + at.f * (shares[at.j] - shares[at.i]);
    return vec4(share, gain, exponent, w);
}

// The sun's share through the crown where the shadow map does not resolve leaves: `blend` (the
// bake's blend of attenuations with its gain and hotspot) off the ring's elevation; the leaf's
// sunlit share on its type's ring where the fragment is (`ring_sun.x`, from `ring_sun_at`),
// times the seen-part gain, capped at 1, raised to the crown's hotspot exponent, at it; mixed
// by the ring's weight between (`lighting::bounce_ring::sun_through_with_ring`). Per fragment:
// the cap and the exponent bend the share, which the rasteriser carries across the leaf only
// while it is linear.
fn through_on_ring(blend: f32, ring_sun: vec4<f32>) -> f32 {
    if ring_sun.w <= 0.0 {
        return blend;
    }
    return blend + ring_sun.w * (pow(clamp(ring_sun.x * ring_sun.y, 0.0, 1.0), ring_sun.z) - blend);
}

// A leaf's bounce factors (front, back) for the sun towards `to_sun`: its type's ring where the
// sun is at the ring's elevation, the bake's basis ratios blended towards the sun where not,
// mixed by `ring_weight` between (`lighting::bounce_ring::ratio_with_ring`).
fn ratio_with_ring(
    basis: array<f32, 28>,
    ring_height: f32,
    ring: array<f32, 28>,
    to_sun: vec3<f32>,
) -> vec2<f32> {
    let blend = ratio_towards(basis, to_sun);
    let w = ring_weight(ring_height, to_sun);
    if w <= 0.0 {
        return blend;
    }
    return blend + w * (ratio_on_ring(ring, to_sun) - blend);
}

// Node `k` of eight u8 nodes packed four to a word, low byte first, in 64ths.
fn hotspot_node(nodes: vec2<u32>, k: u32) -> f32 {
    return f32((nodes[k / 4u] >> (8u * (k % 4u))) & 0xffu) / 64.0;
}

// The crown's hotspot at the phase angle whose cosine is `cos_alpha` (eye · sun), from eight
// nodes evenly over α = 0 … π, linearly in the angle (`lighting::hotspot::at_phase`).
fn hotspot_at(nodes: vec2<u32>, cos_alpha: f32) -> f32 {
    let x = acos(clamp(cos_alpha, -1.0, 1.0)) / PI * 7.0;
    let i = min(u32(floor(x)), 6u);
    let f = clamp(x - f32(i), 0.0, 1.0);
    return mix(hotspot_node(nodes, i), hotspot_node(nodes, i + 1u), f);
}

// The whole of eq. 5.2 for one leaf (`sky + sun * through + bounce` of the result) of unit normal `n` seen from `to_eye`, whose eight
// directions let `attenuation` through, in a crown of extinction `tau` (`model::leaf_radiance`).
// `smooth_envelope` picks eq. 5.7's blend of envelope distances for the sun through the crown
// (`SunThroughCrown::SmoothEnvelope`) over the blend of attenuations (`BlendedAttenuation`);
// `bounce` adds eq. 5.24's bounce, its bins on the leaf's front and back faces scaled by
// `bounce_faces` (the leaf's gathered ratios, `ratio_towards`; 1, 1 for eq. 5.24 as it is;
// `model::bounce_radiance_by_face`). The per-tree constants of the bounce (A·G1, G2, G3 of eq.
// 5.18, 5.25, 5.26: `model::SunBounce`) depend on the sun's direction in the tree's frame, which
// differs between instances turned differently, so they are computed here from it.
fn leaf_radiance(
    optics: LeafOptics,
    n: vec3<f32>,
    to_eye: vec3<f32>,
    attenuation_in: array<f32, 8>,
    tau: f32,
    lights: TreeLights,
    smooth_envelope: bool,
    bounce: bool,
    bounce_faces: vec2<f32>,
) -> LeafLight {
    var attenuation = attenuation_in;
    let seen_front = dot(n, to_eye) >= 0.0;
    // s_max(P, ω_j) = −ln(a_j) / τ (§5.6), a shut bin letting the least a bake stores through.
    var s_max: array<f32, 8>;
    for (var j = 0u; j < 8u; j += 1u) {
        s_max[j] = select(0.0, -log(max(attenuation[j], DARKEST_LIGHT)) / tau, tau > 0.0);
    }
    // Eq. 5.6: the sky and the ground through each bin, the BSDF integrated over the bin.
    var cosines: array<f32, 8>;
    for (var j = 0u; j < 8u; j += 1u) {
        cosines[j] = octant_cosine(n, j);
    }
    var lit_side = optics.reflectance_front;
    var far_side = optics.transmittance_back;
    if !seen_front {
        lit_side = optics.transmittance_front;
        far_side = optics.reflectance_back;
    }
    var sky = vec3(0.0);
    var open = 0.0;
    for (var j = 0u; j < 8u; j += 1u) {
        let radiance = select(lights.ground, lights.sky, direction(j).y > 0.0);
        sky += (lit_side * cosines[j] + far_side * cosines[7u - j]) * (attenuation[j] * radiance);
        open += (cosines[j] + cosines[7u - j]) * attenuation[j];
    }
    var out: LeafLight;
    out.sky = sky / PI;
    out.open = open / (2.0 * PI);
    out.sun = vec3(0.0);
    out.through = 1.0;
    out.bounce = vec3(0.0);
    if all(lights.sun == vec3(0.0)) {
        return out;
    }
    let wl = lights.to_sun;
    // Eq. 5.7's cosine lobes M(ω_l · ω_j) = max(ω_l · ω_j, 0) around the sun.
    var lobes: array<f32, 8>;
    var lobe_sum = 0.0;
    var lobe_mean = vec3(0.0);
    var blended_attenuation = 0.0;
    var blended_s_max = 0.0;
    for (var j = 0u; j < 8u; j += 1u) {
        let d = direction(j);
        lobes[j] = max(dot(wl, d), 0.0);
        lobe_sum += lobes[j];
        lobe_mean += lobes[j] * d;
        blended_attenuation += lobes[j] * attenuation[j];
        blended_s_max += lobes[j] * s_max[j];
    }
    // `model::sun_through_crown`.
    var through = 1.0;
    if lobe_sum > 0.0 {
        if smooth_envelope {
            through = exp(-tau * blended_s_max / lobe_sum);
        } else {
            through = blended_attenuation / lobe_sum;
        }
        lobe_mean /= lobe_sum;
    }
    // Eq. 5.8.
    out.sun = bsdf(optics, n, seen_front, wl) * lights.sun;
    out.through = through;
    if !bounce {
        return out;
    }
    // Eq. 5.11 with eq. 5.24 (`model::bounce_radiance_by_face`), A·G1 with A·ρ = 2τ.
    let rho_bar = optics.reflectance_front + optics.reflectance_back
        + optics.transmittance_front + optics.transmittance_back;
    let crossing = optics.transmittance_front + optics.transmittance_back;
    var bounced = vec3(0.0);
    for (var j = 0u; j < 8u; j += 1u) {
        let d = direction(j);
        let cos_alpha = clamp(dot(d, wl), -1.0, 1.0);
        let alpha = acos(cos_alpha);
        let a_g1 = (rho_bar * (sin(alpha) - alpha * cos_alpha) + crossing * (PI * cos_alpha))
            * (4.0 * tau / (3.0 * PI * 8.0));
        let g3 = tau * (1.0 - dot(d, lobe_mean));
        let sample = a_g1 * lights.sun * through * one_minus_exp_over(g3, s_max[j]);
        let face = select(bounce_faces.y, bounce_faces.x, dot(n, d) >= 0.0);
        bounced += bsdf(optics, n, seen_front, d) * (sample * face);
    }
    out.bounce = bounced;
    return out;
}

// What the tree-lit leaves' vertex stage hands their fragment stage (`leaf.wgsl`,
// `leaf_volume_fragment.wgsl`): Bevy's forward inputs the fragment rebuilds its material input
// from, and the leaf's light divided by the material's base colour (which the fragment
// multiplies back in with the texture).
struct TreeLitVertexOutput {
    @builtin(position) position: vec4<f32>,
    @location(0) world_position: vec4<f32>,
    @location(1) world_normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) sky: vec3<f32>,
    @location(4) sun: vec3<f32>,
    @location(5) bounce: vec3<f32>,
    // The crown's share of the sun (`LeafLight::through`); the distance towards the sun to the
    // plane touching the crown's bounding sphere on the sun's side, and the leaf's size, in
    // world units.
    @location(6) through_reach_size: vec3<f32>,
    @location(7) @interpolate(flat) instance_index: u32,
    // The leaf's sunlit share on its type's ring here, its seen-part gain, the crown's hotspot
    // exponent and the ring's weight (`ring_sun_at`; weight 0: `through` alone).
    @location(8) ring_sun: vec4<f32>,
    // The leaf's open map (`leaf_pulling::leaf_open_map`; all 0: none) and where the vertex
    // lies on its grid (`open_map_at`): the fragment scales the sky by the cell under it.
    @location(9) @interpolate(flat) open_map: vec4<u32>,
    @location(10) open_at: vec2<f32>,
}
