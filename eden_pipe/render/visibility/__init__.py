"""Sky visibility and bounce light baked once per garden, lit by any sky at render time.

The default render's Dind (``render.indirect_samples=0``) is the sky seen from
each point, with the sky hidden where geometry hides it and light bounced off
that geometry in its place. Nothing here depends on the lighting: the bake is
done once per garden (stage ``sky_visibility``) and every lighting and frame
combines it with its own sky and sun.

Where: a garden has millions of tiny faces (lawn blades, leaves), too many to
trace enough rays from each. Two ray sets share the work:

- *outside-in bundles* (``sky_hits``): for ``directions`` stratified sky
  directions, a grid of parallel rays ``spacing_m`` apart enters the garden's
  box from that direction; a face side is hit by about ``V area cos / spacing^2``
  of them, so hit counts give every face side's cosine-weighted visible sky
  (coherent rays: several times cheaper than scattered ones);
- *probes*: faces whose centroids share a cell (``cell_m`` wide,
  ``cell_height_m`` tall: the lawn's height matters more than its extent), whose
  side normals share a major axis and (for opaque faces) which side, once per
  side of each face (faces are two-sided). A probe pools its faces' bundle hits
  into an SH shape, and sends ``rays`` cosine rays from area-sampled points of
  its faces for the bounce.

What (Sloan et al. 2002, precomputed radiance transfer, order 4 SH;
:mod:`eden_pipe.render.sh`):

- per probe ``transfer`` T (16): the cosine-weighted visible sky,
  ``T_i = int V(w) cos(w)/pi Y_i(w) dw``. A sky with SH radiance L gives sky
  irradiance/pi ``T . L``. A pixel's own normal n corrects for the probe's mean
  normal: ``T + v (T_open(n) - T_open(nbar))`` with v the probe's visible fraction;
- per face side ``exposure``: its own visible sky over its probe's (hit counts
  shrunk toward the probe's where few rays reached a tiny face): the probe gives
  the shape, the face the amount; with ``camera_views``, scaled per probe to the
  sky seen at the points that cameras at the rig's height see (``camera_gain``:
  they see the parts of a leaf that open toward them, which see more sky than
  the leaf's average); faces wider than ``lightmap_cell_m`` squared (fence
  planks and rails, trunks, the lawn's soil) take it from their own lightmap
  instead, a grid of nodes over the face (:mod:`eden_pipe.render.lightmap`),
  since their sky changes from their foot to their top;
- per probe ``bounce`` beta (16) and ``tint`` c (3): what the blocked rays hit, as
  light seen from here: ``beta = mean over blocked rays of lum(rho m) (T_hit + t T_hit_back)``
  with rho, t the albedo and translucency of the face hit, T_hit its transfer
  on the side facing us and on the other side (light through leaves), and
  m = 1/(1 - a) a multi-bounce factor from the hit probe's own blocked albedo a.
  The bounce is ``c * beta . (L + E_sun cloud Y(sun))``: sky light that reached
  the hit points, plus sun whose visibility at the hit points is the
  band-limited V(s) cos(s) their transfer holds (a smooth stand-in for their
  sun shadow, exact on average over sun directions). With ``camera_views`` and
  ``seen_bounce``, the points cameras see replace the probe's random points
  (``bounce.camera_bounce``: the camera gain's sky rays, closest-hit, their hits
  lit the same way, shrunk toward the probe's own rays): a camera sees the open
  side of a hedge, whose neighbours are lit, while a probe's rays also leave the
  shaded insides of its cell (docs/realism.md, Bounce). Their colour too: c is
  then the albedo (times m) of what those rays meet, each hit weighted by its
  light under an even sky, where a probe's own c counts every hit alike, lit or
  not (docs/realism.md, "The bounce's colour").

The foliage back side (translucency T) reads the other side's probe, so
transmitted light sees the same sky and bounce model as the front.

The flat land outside the garden's box (the skirt) has a *ground map*
(``GroundGrid``): nodes every ``ground_cell_m`` with their own cosine rays,
blended bilinearly per pixel, since one of its faces spans metres over which
the garden hides less and less of the sky.
"""

# The ray constants every traced batch of the bake shares (bake, ground map, bounce).
EPS = 1e-3  # how far a ray starts off the surface it leaves
RAYS_PER_WAVE = 1 << 20  # the most rays one Embree call (and its arrays) holds
