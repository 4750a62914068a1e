// terratiles viewer: loads a 3D Tiles tileset (default /data/tileset.json) into
// CesiumJS without Cesium ion or any network access, flies to it and shows a
// per-zoom legend.  Automation reads `window.terratiles` (plain data) and may
// call the helpers in `window.terratilesApi`.
//
// URL parameters:
//   tileset=URL    tileset.json to load (default /data/tileset.json)
//   terrain=URL    instead: a terrain layer shown as the globe's terrain with the imagery
//                  draped on it: a quantized-mesh layer.json (CesiumTerrainProvider) or the
//                  tileset.json of 3D Tiles terrain (Cesium3DTilesTerrainProvider)
//   sse=N          maximumScreenSpaceError (default 16)
//   bv=1           show tile bounding volumes
//   colorize=1     colour tiles randomly (debugColorizeTiles)
//   wireframe=1    render tile meshes as wireframe
//   time=ISO8601   scene time, i.e. sun position (default 2024-06-21T10:00:00Z)
/* global Cesium */
(function () {
  'use strict';

  const params = new URLSearchParams(window.location.search);
  const terrainUrl = params.get('terrain');
  const tilesetUrl = terrainUrl || params.get('tileset') || '/data/tileset.json';
  const maximumScreenSpaceError = Number(params.get('sse') || 16);
  const sceneTime = params.get('time') || '2024-06-21T10:00:00Z';

  // ---- status object for automation (plain, JSON-serialisable data) --------
  const status = {
    tilesetUrl,
    ready: false, // initial view reached and all its tiles loaded
    error: null, // tileset could not be loaded
    renderError: null, // CesiumJS stopped rendering (shader/WebGL error)
    tilesLoaded: 0, // tileLoad events (content loads, re-loads included)
    tilesUnloaded: 0,
    failedTiles: [], // [{url, message}]
    // Per level: the zoom of terratiles tiles (from their content names), else tree depth.
    tilesByLevel: {}, // level -> number of distinct tiles whose content loaded
    renderedByLevel: {}, // level -> number of distinct tiles rendered at least once
    visibleByLevel: {}, // level -> tiles rendered in the last frame
    geometricErrorByLevel: {}, // level -> geometric error of a tile seen at that level
    maxLevelSeen: -1,
    allTilesLoaded: false, // tileset.tilesLoaded in the last frame
    allTilesLoadedCount: 0, // allTilesLoaded events
    initialTilesLoaded: false,
    pendingRequests: 0,
    tilesProcessing: 0,
    frame: 0,
    stableFrames: 0, // consecutive frames with camera still and all tiles loaded
    center: null, // {lon, lat, height} deg/deg/m: root region centre (or bounding sphere)
    region: null, // root region in degrees/metres, if the root uses a region
    boundingSphere: null, // {lon, lat, height, radius} of the tileset bounding sphere
    camera: null, // {lon, lat, height, headingDeg, pitchDeg}
  };
  window.terratiles = status;

  const loadedSets = new Map(); // depth -> Set<Cesium3DTile>
  const renderedSets = new Map();
  let frameVisible = {};

  // A tile's row in the legend: its zoom, read from a terratiles content name
  // (tiles/z/x/y.glb, or tiles/west|east/z/x/y.glb with --implicit), else its depth in the
  // tree (another tileset). null for a tile with nothing to draw (an implicit subtree, an
  // external tileset): implicit tilesets add such placeholder tiles, so depth is not zoom.
  const zoomInName = /(?:^|\/)tiles\/(?:(?:west|east)\/)?(\d+)\/\d+\/\d+\.glb(?:$|\?)/;
  function tileLevel(tile) {
    const url = (tile.content && tile.content.url) || '';
    if (/\.(subtree|json)(?:$|\?)/.test(url)) return null;
    const match = zoomInName.exec(url);
    if (match) return Number(match[1]);
    let d = 0;
    for (let t = tile.parent; t; t = t.parent) d++;
    return d;
  }
  function addToSet(map, depth, tile) {
    let s = map.get(depth);
    if (!s) map.set(depth, (s = new Set()));
    s.add(tile);
    return s.size;
  }
  function noteLevel(tile, depth) {
    if (depth > status.maxLevelSeen) status.maxLevelSeen = depth;
    if (!(depth in status.geometricErrorByLevel)) {
      status.geometricErrorByLevel[depth] = tile.geometricError;
    }
  }

  // ---- viewer --------------------------------------------------------------
  const viewer = new Cesium.Viewer('cesiumContainer', {
    baseLayer: Cesium.ImageryLayer.fromProviderAsync(
      Cesium.TileMapServiceImageryProvider.fromUrl(
        Cesium.buildModuleUrl('Assets/Textures/NaturalEarthII'),
      ),
    ),
    // no `terrain` option: WGS84 ellipsoid, nothing is fetched from ion
    baseLayerPicker: false,
    geocoder: false,
    animation: false,
    timeline: false,
    homeButton: false,
    sceneModePicker: false,
    navigationHelpButton: false,
    fullscreenButton: false,
    infoBox: false,
    selectionIndicator: false,
    shouldAnimate: false,
    requestRenderMode: false,
    contextOptions: { webgl: { preserveDrawingBuffer: true } },
  });
  // fixed sun position so screenshots are reproducible
  viewer.clock.currentTime = Cesium.JulianDate.fromIso8601(sceneTime);
  viewer.clock.shouldAnimate = false;
  const scene = viewer.scene;
  scene.renderError.addEventListener((_scene, err) => {
    status.renderError = (err && err.message) || String(err);
  });

  // ---- legend --------------------------------------------------------------
  const legendBody = document.getElementById('legendBody');
  let lastLegend = 0;
  function fmt(n, digits) {
    return Number.isFinite(n) ? n.toFixed(digits) : '-';
  }
  function updateLegend(force) {
    const now = performance.now();
    if (!force && now - lastLegend < 250) return;
    lastLegend = now;
    const depths = new Set([
      ...Object.keys(status.tilesByLevel),
      ...Object.keys(status.renderedByLevel),
    ]);
    const sorted = [...depths].map(Number).sort((a, b) => a - b);
    let state;
    if (status.error) state = `<span class="err">error: ${escapeHtml(status.error)}</span>`;
    else if (!status.ready) state = 'loading&hellip;';
    else state = status.allTilesLoaded ? '<span class="ok">all tiles loaded</span>' : 'loading tiles&hellip;';
    let html = `${escapeHtml(tilesetUrl)}<br>${state}<br>`;
    html += '<table><tr><th>zoom</th><th>geom.err</th><th>loaded</th><th>visible</th><th>rendered</th></tr>';
    for (const d of sorted) {
      html +=
        `<tr><td>${d}</td><td>${fmt(status.geometricErrorByLevel[d], 1)}</td>` +
        `<td>${status.tilesByLevel[d] || 0}</td><td>${status.visibleByLevel[d] || 0}</td>` +
        `<td>${status.renderedByLevel[d] || 0}</td></tr>`;
    }
    html += '</table>';
    html += `tiles loaded: ${status.tilesLoaded}, pending: ${status.pendingRequests}, processing: ${status.tilesProcessing}<br>`;
    const nf = status.failedTiles.length;
    html += `failed tiles: <span class="${nf ? 'err' : 'ok'}">${nf}</span>`;
    if (status.center) {
      html += `<br>centre: ${fmt(status.center.lat, 4)}&deg;N ${fmt(status.center.lon, 4)}&deg;E`;
    }
    if (status.camera) html += `<br>camera height: ${fmt(status.camera.height, 0)} m`;
    legendBody.innerHTML = html;
  }
  function escapeHtml(s) {
    return String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' })[c]);
  }

  // ---- per-frame bookkeeping -----------------------------------------------
  let tileset = null;
  let terrainProvider = null;
  let zoomDone = false;
  const lastCamPos = new Cesium.Cartesian3();
  const lastCamDir = new Cesium.Cartesian3();

  scene.preRender.addEventListener(() => {
    frameVisible = {};
  });
  scene.postRender.addEventListener(() => {
    status.frame++;
    status.visibleByLevel = frameVisible;
    const cam = viewer.camera;
    const carto = cam.positionCartographic;
    status.camera = {
      lon: Cesium.Math.toDegrees(carto.longitude),
      lat: Cesium.Math.toDegrees(carto.latitude),
      height: carto.height,
      headingDeg: Cesium.Math.toDegrees(cam.heading),
      pitchDeg: Cesium.Math.toDegrees(cam.pitch),
    };
    const moved =
      !Cesium.Cartesian3.equalsEpsilon(cam.positionWC, lastCamPos, 0, 1e-3) ||
      !Cesium.Cartesian3.equalsEpsilon(cam.directionWC, lastCamDir, 1e-9);
    Cesium.Cartesian3.clone(cam.positionWC, lastCamPos);
    Cesium.Cartesian3.clone(cam.directionWC, lastCamDir);
    const loaded = tileset ? tileset.tilesLoaded : terrainProvider ? scene.globe.tilesLoaded : null;
    if (loaded !== null) {
      status.allTilesLoaded = loaded;
      status.stableFrames = !moved && loaded ? status.stableFrames + 1 : 0;
      if (zoomDone && !status.ready && status.stableFrames >= 5) {
        status.ready = true;
        updateLegend(true);
        console.log('terratiles: initial view loaded');
      }
    }
    updateLegend(false);
  });

  // ---- tileset -------------------------------------------------------------
  function regionCenter(json) {
    const bv = json && json.root && json.root.boundingVolume;
    if (!bv || !Array.isArray(bv.region) || bv.region.length !== 6) return null;
    const [w, s, e, n, minH, maxH] = bv.region;
    const deg = Cesium.Math.toDegrees;
    status.region = { west: deg(w), south: deg(s), east: deg(e), north: deg(n), minHeight: minH, maxHeight: maxH };
    let lonC = (w + e) / 2;
    if (e < w) lonC = Cesium.Math.negativePiToPi(lonC + Math.PI); // crosses the antimeridian
    return { lon: deg(lonC), lat: deg((s + n) / 2), height: (minH + maxH) / 2 };
  }

  // A terrain layer as the globe's terrain: tile failures counted, the view on the finest
  // zoom's tiles (layer.json's last `available` ranges, or the same in a 3D Tiles terrain
  // tileset's extras).
  async function loadTerrain() {
    try {
      const resp = await fetch(terrainUrl, { cache: 'no-store' });
      if (!resp.ok) throw new Error(`HTTP ${resp.status} for ${terrainUrl}`);
      const json = await resp.json();
      const tiles3d = /tileset\.json$/.test(terrainUrl);
      const layer = tiles3d ? json.extras.terratiles : json;
      status.terrainFormat = tiles3d ? '3d-tiles-terrain' : 'quantized-mesh';
      terrainProvider = tiles3d
        ? await Cesium.Cesium3DTilesTerrainProvider.fromUrl(terrainUrl, { requestVertexNormals: true })
        : await Cesium.CesiumTerrainProvider.fromUrl(terrainUrl.replace(/layer\.json$/, ''), {
          requestVertexNormals: true,
        });
      terrainProvider.errorEvent.addEventListener((err) => {
        const where = err && err.level !== undefined ? `${err.level}/${err.x}/${err.y}` : terrainUrl;
        status.failedTiles.push({ url: where, message: String((err && err.message) || err) });
        console.error(`terratiles: terrain tile failed: ${where}`);
        updateLegend(true);
      });
      viewer.terrainProvider = terrainProvider;
      scene.globe.enableLighting = true;  // the tiles' normals, lit by the fixed sun
      window.terratilesApi.terrainProvider = terrainProvider;
      const zoom = layer.available.length - 1;
      const size = 180 / 2 ** zoom;
      let w = 180, s = 90, e = -180, n = -90;
      for (const r of layer.available[zoom]) {
        w = Math.min(w, -180 + r.startX * size);
        e = Math.max(e, -180 + (r.endX + 1) * size);
        s = Math.min(s, -90 + r.startY * size);
        n = Math.max(n, -90 + (r.endY + 1) * size);
      }
      status.region = { west: w, south: s, east: e, north: n };
      status.center = { lon: (w + e) / 2, lat: (s + n) / 2, height: 0 };
      // Tilted over the middle (at the terrain's height there), from about the rectangle's
      // diagonal, so the relief shows.
      const middle = Cesium.Cartographic.fromDegrees((w + e) / 2, (s + n) / 2);
      const [ground] = await Cesium.sampleTerrainMostDetailed(terrainProvider, [middle]);
      const diagonal = Cesium.Cartesian3.distance(Cesium.Cartesian3.fromDegrees(w, s), Cesium.Cartesian3.fromDegrees(e, n));
      window.terratilesApi.lookAt((w + e) / 2, (s + n) / 2, Number.isFinite(ground.height) ? ground.height : 0,
        0.8 * diagonal, -35);
      zoomDone = true;
    } catch (e) {
      status.error = (e && e.message) || String(e);
      console.error(`terratiles: failed to load ${terrainUrl}: ${status.error}`);
    }
    updateLegend(true);
  }

  async function load() {
    if (terrainUrl) return loadTerrain();
    try {
      // The raw JSON gives the root region (the tileset's own notion of its extent).
      const resp = await fetch(tilesetUrl, { cache: 'no-store' });
      if (!resp.ok) throw new Error(`HTTP ${resp.status} for ${tilesetUrl}`);
      const json = await resp.json();
      const rc = regionCenter(json);

      tileset = await Cesium.Cesium3DTileset.fromUrl(tilesetUrl, {
        maximumScreenSpaceError,
        debugShowBoundingVolume: params.get('bv') === '1',
        debugColorizeTiles: params.get('colorize') === '1',
        debugWireframe: params.get('wireframe') === '1',
        enableDebugWireframe: params.get('wireframe') === '1',
      });

      tileset.tileLoad.addEventListener((tile) => {
        status.tilesLoaded++;
        const d = tileLevel(tile);
        if (d === null) return;
        noteLevel(tile, d);
        status.tilesByLevel[d] = addToSet(loadedSets, d, tile);
      });
      tileset.tileUnload.addEventListener(() => {
        status.tilesUnloaded++;
      });
      tileset.tileFailed.addEventListener((err) => {
        status.failedTiles.push({ url: String(err.url), message: String(err.message) });
        console.error(`terratiles: tile failed: ${err.url}: ${err.message}`);
        updateLegend(true);
      });
      tileset.tileVisible.addEventListener((tile) => {
        const d = tileLevel(tile);
        if (d === null) return;
        noteLevel(tile, d);
        frameVisible[d] = (frameVisible[d] || 0) + 1;
        status.renderedByLevel[d] = addToSet(renderedSets, d, tile);
      });
      tileset.loadProgress.addEventListener((pending, processing) => {
        status.pendingRequests = pending;
        status.tilesProcessing = processing;
      });
      tileset.allTilesLoaded.addEventListener(() => {
        status.allTilesLoadedCount++;
      });
      tileset.initialTilesLoaded.addEventListener(() => {
        status.initialTilesLoaded = true;
      });

      scene.primitives.add(tileset);
      window.terratilesApi.tileset = tileset;

      const bs = tileset.boundingSphere;
      const bsc = Cesium.Cartographic.fromCartesian(bs.center);
      status.boundingSphere = bsc
        ? {
            lon: Cesium.Math.toDegrees(bsc.longitude),
            lat: Cesium.Math.toDegrees(bsc.latitude),
            height: bsc.height,
            radius: bs.radius,
          }
        : { lon: null, lat: null, height: null, radius: bs.radius };
      status.center = rc || (bsc ? { lon: status.boundingSphere.lon, lat: status.boundingSphere.lat, height: bsc.height } : null);

      // Overview: the whole tileset, tilted so the relief shows.
      await viewer.zoomTo(
        tileset,
        new Cesium.HeadingPitchRange(0, Cesium.Math.toRadians(-40), 2.2 * bs.radius),
      );
      zoomDone = true;
    } catch (e) {
      status.error = (e && e.message) || String(e);
      console.error(`terratiles: failed to load ${tilesetUrl}: ${status.error}`);
    }
    updateLegend(true);
  }

  // ---- helpers for automation ----------------------------------------------
  window.terratilesApi = {
    viewer,
    tileset: null,
    // Look at (lon, lat, height) from `range` metres away; camera stays free afterwards.
    lookAt(lonDeg, latDeg, heightM, rangeM, pitchDeg = -89.5, headingDeg = 0) {
      const target = Cesium.Cartesian3.fromDegrees(lonDeg, latDeg, heightM);
      viewer.camera.lookAt(
        target,
        new Cesium.HeadingPitchRange(
          Cesium.Math.toRadians(headingDeg),
          Cesium.Math.toRadians(pitchDeg),
          rangeM,
        ),
      );
      viewer.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
      status.stableFrames = 0;
    },
    zoomToTileset(pitchDeg = -40, rangeFactor = 2.2) {
      status.stableFrames = 0;
      if (!tileset) return Promise.resolve(false);
      return viewer
        .zoomTo(
          tileset,
          new Cesium.HeadingPitchRange(0, Cesium.Math.toRadians(pitchDeg), rangeFactor * tileset.boundingSphere.radius),
        )
        .then(() => true);
    },
    // Height (m above the ellipsoid) of the tileset surface at lon/lat, or null.
    // The globe is hidden while sampling so only the tileset can be hit.
    async sampleHeight(lonDeg, latDeg) {
      if (!scene.sampleHeightSupported) throw new Error('scene.sampleHeight is not supported');
      const globeShow = scene.globe.show;
      scene.globe.show = false;
      try {
        const res = await scene.sampleHeightMostDetailed([Cesium.Cartographic.fromDegrees(lonDeg, latDeg)]);
        const h = res && res[0] ? res[0].height : undefined;
        return Number.isFinite(h) ? h : null;
      } finally {
        scene.globe.show = globeShow;
      }
    },
    // Heights (m above the ellipsoid) of the terrain at [[lon, lat], ...] degrees, at its
    // finest tiles (sampleTerrainMostDetailed); null where it has none.
    async sampleTerrain(points) {
      if (!terrainProvider) throw new Error('no terrain layer loaded (terrain=URL)');
      const cartographics = points.map(([lon, lat]) => Cesium.Cartographic.fromDegrees(lon, lat));
      const sampled = await Cesium.sampleTerrainMostDetailed(terrainProvider, cartographics);
      return sampled.map((c) => (Number.isFinite(c.height) ? c.height : null));
    },
    // Forget "rendered"/"loaded" tallies (e.g. before a new camera sweep).
    resetCounters() {
      loadedSets.clear();
      renderedSets.clear();
      status.tilesByLevel = {};
      status.renderedByLevel = {};
    },
  };

  load();
})();
