// The report's 3-D view (engine/report.py, view_section): plotly.js and the mesh arrive gzipped in the page;
// the elements whose centroid lies on the kept side of a movable axis plane are drawn whole, the faces they
// do not share with another drawn element coloured by the chosen field; the element under the pointer shows
// its audit.
(async function () {
  const audit = document.getElementById("view-audit");
  try {
    const unpack = async (id) => new Response(new Blob([Uint8Array.from(
      atob(document.getElementById(id).textContent), (c) => c.charCodeAt(0))]).stream()
      .pipeThrough(new DecompressionStream("gzip"))).arrayBuffer();
    const library = document.createElement("script");
    library.textContent = new TextDecoder().decode(await unpack("view-plotly"));
    document.head.appendChild(library);
    const meta = JSON.parse(document.getElementById("view-meta").textContent);
    const buffer = await unpack("view-mesh");
    const kinds = { f4: Float32Array, i4: Int32Array, i2: Int16Array };
    const a = {};
    for (const [name, [offset, kind, size]] of Object.entries(meta.arrays)) {
      a[name] = new kinds[kind](buffer.slice(offset, offset + size * kinds[kind].BYTES_PER_ELEMENT));
    }
    const P = a.points, T = a.tets, m = T.length / 4;
    const centroid = new Float32Array(3 * m);
    for (let t = 0; t < m; t++) for (let d = 0; d < 3; d++) {
      let s = 0;
      for (let v = 0; v < 4; v++) s += P[3 * T[4 * t + v] + d];
      centroid[3 * t + d] = s / 4;
    }
    const low = [Infinity, Infinity, Infinity], high = [-Infinity, -Infinity, -Infinity];
    centroid.forEach((c, i) => { low[i % 3] = Math.min(low[i % 3], c); high[i % 3] = Math.max(high[i % 3], c); });
    const [X, Y, Z] = [0, 1, 2].map((d) => P.filter((_, i) => i % 3 === d));
    const n = meta.palette.length, colourOf = (w) => meta.palette[((w % n) + n) % n];   // as the cut figures
    const FACES = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    const fields = {
      h_target: ["target size h_target", a.h_target], size_ratio: ["h_actual / h_target", a.size_ratio],
      quality: ["min dihedral (°)", a.quality],
    };
    const ui = (id) => document.getElementById(id);
    const slider = () => [ui("view-axis").selectedIndex, Number(ui("view-cut").value) / 1000];
    const [start, at] = meta.focus;                           // the first cut: through the finest element
    ui("view-axis").value = "xyz"[start];
    ui("view-cut").value = Math.round(1000 * (at - low[start]) / ((high[start] - low[start]) || 1));
    let shown = [];
    const eye = { x: 0.6, y: 0.6, z: 0.6 };                   // looking at that cut
    eye["xyz"[start]] = 1.3;

    function draw() {
      const [axis, fraction] = slider(), side = Number(ui("view-side").value);
      const plane = low[axis] + fraction * (high[axis] - low[axis]);
      const kept = new Uint8Array(m);
      for (let t = 0; t < m; t++) kept[t] = side * (centroid[3 * t + axis] - plane) <= 0 ? 1 : 0;
      const I = [], J = [], K = [], ex = [], ey = [], ez = [];
      shown = [];
      for (let t = 0; t < m; t++) {
        if (!kept[t]) continue;
        for (let f = 0; f < 4; f++) {
          const other = a.neighbours[4 * t + f];
          if (other >= 0 && kept[other]) continue;
          const [p, q, r] = FACES[f].map((v) => T[4 * t + v]);
          I.push(p); J.push(q); K.push(r); shown.push(t);
          for (const v of [p, q, r, p]) { ex.push(P[3 * v]); ey.push(P[3 * v + 1]); ez.push(P[3 * v + 2]); }
          ex.push(null); ey.push(null); ez.push(null);
        }
      }
      const colour = ui("view-colour").value;
      const surface = {
        type: "mesh3d", x: X, y: Y, z: Z, i: I, j: J, k: K, flatshading: true, hoverinfo: "none",
        lighting: { ambient: 0.75, diffuse: 0.5, specular: 0.05 },
      };
      const legend = ui("view-legend");
      if (colour === "winner") {          // categories: 0 no pattern, 1 + the index of the winning pattern
        const count = meta.patterns.length + 1;
        const steps = Array.from({ length: count }, (_, c) => [[c / count, colourOf(c - 1)], [(c + 1) / count, colourOf(c - 1)]]);
        Object.assign(surface, { intensity: shown.map((t) => a.winner[t] + 1), intensitymode: "cell",
                                 cmin: -0.5, cmax: count - 0.5, colorscale: steps.flat(), showscale: false });
        const seen = [...new Set(shown.map((t) => a.winner[t]))].sort((p, q) => p - q);
        legend.replaceChildren(...seen.map((w) => {
          const entry = document.createElement("span");
          entry.style.borderLeft = `1em solid ${colourOf(w)}`;
          entry.style.margin = "0 0.5em";
          entry.textContent = " " + (w >= 0 ? meta.patterns[w].id : "none");
          return entry;
        }));
      } else {
        const [title, values] = fields[colour];
        Object.assign(surface, {
          intensity: shown.map((t) => values[t]), intensitymode: "cell", colorscale: "Viridis",
          colorbar: { title: { text: title }, len: 0.8 },
        });
        legend.replaceChildren();
      }
      const edges = { type: "scatter3d", mode: "lines", x: ex, y: ey, z: ez, hoverinfo: "skip",
                      line: { color: "#333333", width: 1 }, showlegend: false };
      Plotly.react("view", [surface, edges], {
        margin: { l: 0, r: 0, t: 0, b: 0 }, uirevision: "keep",
        scene: { aspectmode: "data", camera: { eye: eye }, xaxis: { title: { text: "x" } }, yaxis: { title: { text: "y" } },
                 zaxis: { title: { text: "z" } } },
      }, { displaylogo: false });
    }

    function explain(t) {
      const w = a.winner[t], r = a.runner_up[t], number = (x) => Number(x).toPrecision(4);
      const lines = [`element ${a.element[t]} (0-based), centroid (${[0, 1, 2].map((d) => number(centroid[3 * t + d])).join(", ")})`];
      if (w >= 0) {
        const p = meta.patterns[w], zone = meta.zones[a.zone[t]];
        lines.push(`pattern: ${p.id} (pattern '${p.pattern}')${p.feature ? " on " + p.feature : ""}`,
                   `zone: '${zone.id}'`, `membership: mu = ${number(a.winner_mu[t])}`);
        lines.push(`rule: placed at ${p.placed}; zone at ${zone.source}`);
      } else {
        lines.push("pattern: none reaches here, the global size applies");
      }
      lines.push(`h_target = ${number(a.h_target[t])}, h_actual = ${number(a.h_actual[t])} (ratio ${number(a.size_ratio[t])})`,
                 `runner-up: ${r >= 0 ? meta.patterns[r].id + ", mu = " + number(a.runner_up_mu[t]) : "none"}`,
                 `graded: ${a.graded[t] ? "yes, the gradation limit g = " + meta.gradation_limit + " lowered the size by " + number(a.gradation[t]) : "no"}`,
                 `quality: minimum dihedral angle ${number(a.quality[t])}°`);
      return lines.join("\n");
    }

    draw();
    const pick = (event) => {
      const point = event.points.find((p) => p.curveNumber === 0);
      if (point) audit.textContent = explain(shown[point.pointNumber]);
    };
    ui("view").on("plotly_hover", pick);
    ui("view").on("plotly_click", pick);
    for (const id of ["view-colour", "view-axis", "view-cut", "view-side"]) ui(id).addEventListener("input", draw);
    audit.textContent = "hover over or click an element for its audit";
    document.body.dataset.view = "ready";
  } catch (error) {
    audit.textContent = "the 3-D view failed: " + error;
    console.error(error);
  }
})();
