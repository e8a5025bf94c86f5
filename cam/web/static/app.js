// cam machine page: talks to /api (JSON) and listens to /api/events (server-sent events).
"use strict";

(function () {
  const $ = (id) => document.getElementById(id);
  const token = new URLSearchParams(location.search).get("token") || "";
  const page = { job: null, kind: null, planned: null, profile: null, state: null, promptShown: null,
                 logSeq: 0, estopAt: 0 };

  function withToken(url) {
    if (!token) return url;
    return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
  }

  function showError(text) {
    $("error-text").textContent = text;
    $("error").hidden = false;
  }
  function clearError() { $("error").hidden = true; $("error-text").textContent = ""; }

  async function api(path, { json, form, method } = {}) {
    // the browser adds this page's Origin to a POST; X-Requested-With tells the server it is no cross-site form
    const opts = { method: method || (json || form ? "POST" : "GET"), headers: { "X-Requested-With": "cam" } };
    if (token) opts.headers["X-Cam-Token"] = token;
    if (json !== undefined) { opts.headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(json); }
    if (form !== undefined) opts.body = form;
    let resp;
    try {
      resp = await fetch(path, opts);
    } catch (e) {
      showError("the server cannot be reached (" + e.message + ")");
      throw e;
    }
    let data = null;
    try { data = await resp.json(); } catch (e) { data = null; }
    if (!resp.ok) {
      const msg = (data && data.error) ? data.error : ("HTTP " + resp.status);
      showError(msg + " (HTTP " + resp.status + ")");
      const err = new Error(msg); err.status = resp.status; throw err;
    }
    return data;
  }

  function hms(s) {
    s = Math.max(0, Math.round(s || 0));
    const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = s % 60;
    return h + ":" + String(m).padStart(2, "0") + ":" + String(sec).padStart(2, "0");
  }

  // -- job: upload, options, plan ------------------------------------------------
  // The job-options form is made from the options' schema (GET /api/options, cam/options.py; issue #47 point 6):
  // one field per option, named by it, labelled with its label, unit and range, its help under it, in a fieldset
  // per group; only the options of the loaded file's kind show, each with that kind's default as its placeholder.
  // A new option of the schema is on the page with no code here: its type alone picks its widget.  Ranges are
  // checked by the server, which refuses a value out of range in one line (the error banner).  The rules between
  // options (cam/options.py RULES: one depth, ...) come with the schema, each option with its own: a form that
  // breaks one is refused here in the server's words, its fields marked, before it is sent (the server checks
  // them again).
  const schema = { byName: {}, ready: Promise.resolve() };
  // options whose field is elsewhere on the page: the file read as a kind (the Read as select, by the file)
  const ELSEWHERE = { kind: "read-as" };
  // a cutter ("tool" type): its shape, and the parts of that shape, or a spec typed in (which wins)
  const TOOL_SHAPES = [["", "default"], ["point", "point (the thesis)"], ["flat", "flat end mill"],
                       ["ball", "ball end mill"], ["v", "V bit"]];
  const TOOL_PARTS = [["diameter", "Diameter (mm; a V bit's shank, empty: 1/8 inch)", "1", "flat ball v"],
                      ["angle", "Angle (degrees, included)", "60", "v"], ["tip", "Tip (mm, 0: sharp)", "0.1", "v"]];
  const NUMERIC = ["whole", "number", "wholes", "numbers", "points", "digits", "size"];

  function applies(name, kind) {
    const o = schema.byName[name];
    return !kind || !o || o.kinds.includes(kind);
  }

  // an option's field id: opt- and its command-line flag (--cut-depth: opt-cut-depth; a cutter's spec: -spec)
  function fieldId(o) { return "opt-" + o.flag.replace(/^-+/, ""); }

  // a value of the schema as typed in its field (2:4, 80x40, 1,2;3,4, 0,0,0)
  function asText(o, v) {
    if (v === null || v === undefined || typeof v === "boolean") return "";
    if (!Array.isArray(v)) return String(v);
    if (o.type === "points") return v.map((p) => p.join(",")).join("; ");
    return v.join(o.type === "digits" ? ":" : o.type === "size" ? "x" : ",");
  }

  function make(tag, props, ...children) {
    const el = document.createElement(tag);
    Object.assign(el, props || {});
    children.forEach((c) => el.append(c));
    return el;
  }

  function labelText(o) {
    const about = [o.unit, o.range].filter((v) => v).join(", ");
    return o.label + (o.metavar && !["whole", "number", "text", "tool"].includes(o.type) ? " " + o.metavar : "") +
      (about ? " (" + about + ")" : "");
  }

  function toolField(o, label) {
    const id = fieldId(o);
    const shape = make("select", { id: id + "-shape" });
    TOOL_SHAPES.forEach(([v, t]) => shape.append(make("option", { value: v, textContent: t })));
    label.append(make("label", {}, "Cutter", shape));
    TOOL_PARTS.forEach(([part, text, value, shapes]) => {
      const part_label = make("label", {}, text, make("input", { id: id + "-" + part, value: value, inputMode: "decimal" }));
      part_label.dataset.shapes = shapes;
      label.append(part_label);
    });
    const spec = make("input", { id: id + "-spec", name: o.name, placeholder: "ball:1, flat:2, v:60:0.1" });
    label.append(make("label", {}, "or tool spec", spec));
    const showParts = () => label.querySelectorAll("label[data-shapes]").forEach((l) => {
      l.hidden = !l.dataset.shapes.split(" ").includes(shape.value);
    });
    shape.addEventListener("change", showParts);
    showParts();
  }

  // the profile option names a file: the page uploads it (role "profile") and sends its upload id
  function profileField(o, label) {
    const input = make("input", { id: "profile-file", type: "file", accept: ".png,.bmp,.jpg,.jpeg,.tif,.tiff,.csv,.txt" });
    const button = make("label", { className: "filebtn" }, o.label + " file (drawing or CSV)", input);
    label.append(button, make("div", { id: "profile-name", className: "muted" }));
    input.addEventListener("change", async (ev) => {
      const file = ev.target.files[0];
      if (!file) return;
      clearError();
      try {
        const r = await upload(file, "profile");
        page.profile = r.job;
        $("profile-name").textContent = "profile: " + r.name;
        if (page.job) await planJob();
      } catch (e) {
        page.profile = null;
        $("profile-name").textContent = "";
      } finally {
        ev.target.value = "";
      }
    });
  }

  // one option's field, in a wrapper that carries its name (data-option): shown or hidden by the file's kind
  function optionField(o) {
    const id = fieldId(o);
    let wrap;
    if (!o.web) {  // a file on the machine that runs cam: the command line's
      wrap = make("p", { className: "muted", textContent: o.label + ": on the command line only (" + o.flag + ")" });
    } else if (o.type === "flag") {
      wrap = make("div", {}, make("label", { className: "check" }, make("input", { id: id, name: o.name, type: "checkbox" }),
                                  " " + o.label));
    } else if (o.type === "tool") {
      wrap = make("div", { className: "tool-field" });
      toolField(o, wrap);
    } else if (o.name === "profile") {
      wrap = make("div");
      profileField(o, wrap);
    } else if (o.type === "choice") {
      const select = make("select", { id: id, name: o.name });
      select.append(make("option", { value: "", textContent: "default" }));
      o.choices.forEach((c) => select.append(make("option", { value: c, textContent: c })));
      wrap = make("label", {}, labelText(o), select);
    } else {
      const input = make("input", { id: id, name: o.name });
      if (NUMERIC.includes(o.type)) input.inputMode = ["whole", "wholes", "points"].includes(o.type) ? "numeric" : "decimal";
      wrap = make("label", {}, labelText(o), input);
    }
    wrap.dataset.option = o.name;
    wrap.title = o.help;
    if (o.web) wrap.append(make("small", { className: "muted setting-help", textContent: o.help }));  // no hover on a phone
    return wrap;
  }

  // the form: a fieldset per group, in the schema's order
  function buildForm(options) {
    const box = $("options-fields");
    box.textContent = "";
    const groups = {};
    options.forEach((o) => {
      if (ELSEWHERE[o.name]) { $(ELSEWHERE[o.name]).dataset.option = o.name; return; }
      if (!groups[o.group]) {
        groups[o.group] = make("fieldset", {}, make("legend", { textContent: o.group }));
        groups[o.group].dataset.group = o.group;
        box.append(groups[o.group]);
      }
      groups[o.group].append(optionField(o));
    });
  }

  function loadSchema() {
    return Promise.all([api("/api/options"), api("/api/kinds")]).then(([options, kinds]) => {
      options.forEach((o) => { schema.byName[o.name] = o; });
      showKinds(kinds);
      buildForm(options);
      showKind(page.kind);
    }, () => {});
  }

  // the file kinds (GET /api/kinds, cam/kinds/): the "Read as" list, what --kind NAME reads a file as
  function showKinds(kinds) {
    const select = $("read-as");
    schema.forcedKind = {};
    kinds.forEach((k) => {
      schema.forcedKind[k.forced_as] = k.name;
      const option = document.createElement("option");
      option.value = k.forced_as;
      option.textContent = k.title;
      select.append(option);
    });
    if (!page.job) $("job-name").textContent = kinds.map((k) => k.title).join(", ");
  }

  // the options of the kind show (every option before a file is loaded), with the kind's defaults as placeholders
  function showKind(kind) {
    document.querySelectorAll("#options-fields [data-option]").forEach((wrap) => {
      const o = schema.byName[wrap.dataset.option];
      wrap.style.display = applies(o.name, kind) ? "" : "none";
      const shown = asText(o, kind && o.defaults[kind] !== undefined ? o.defaults[kind] : o.default);
      const field = wrap.querySelector('[name="' + o.name + '"]');
      if (!field || o.type === "tool") return;
      if (field.tagName === "SELECT") field.options[0].textContent = shown ? "default (" + shown + ")" : "default";
      else if (field.type !== "checkbox") field.placeholder = shown ? shown : (o.metavar || "");
    });
    document.querySelectorAll("#options-fields fieldset").forEach((fs) => {
      fs.hidden = !Array.from(fs.querySelectorAll("[data-option]")).some((w) => w.style.display !== "none");
    });
  }

  // a cutter's spec: the spec typed in wins; else the shape and its parts ("": not given)
  function toolSpec(o) {
    const id = fieldId(o), val = (part) => $(id + "-" + part).value.trim();
    if (val("spec")) return val("spec");
    const shape = val("shape");
    if (shape === "flat" || shape === "ball") return shape + ":" + val("diameter");
    if (shape === "v") {
      const d = val("diameter");
      return "v:" + val("angle") + ":" + (val("tip") || "0") + (d ? ":" + d : "");
    }
    return shape;  // "point" or ""
  }

  // the options that apply to the kind and are given: each read from its field (a box ticked, a value typed or
  // chosen, a cutter, the profile uploaded); what is left empty is not sent (the kind's default)
  function collectOptions() {
    const kind = page.kind;
    const out = {};
    Object.values(schema.byName).forEach((o) => {
      if (!o.web || ELSEWHERE[o.name] || !applies(o.name, kind)) return;
      let v;
      if (o.type === "tool") v = toolSpec(o);
      else if (o.name === "profile") v = page.profile || "";
      else {
        const el = $("options-fields").querySelector('[name="' + o.name + '"]');
        if (!el) return;
        v = el.type === "checkbox" ? el.checked : el.value.trim();
      }
      if (v !== "" && v !== false) out[o.name] = v;
    });
    if ($("read-as").value) out.kind = $("read-as").value;  // cam drill --kind: the file read as this kind
    return out;
  }

  // whether an option's value, as collectOptions sends it, counts for its rules: set, and not to its default
  // (cam.options.given)
  function given(o, v) {
    if (v === undefined || v === "" || v === false) return false;
    if (v === true) return o.default !== true;
    if (["whole", "number"].includes(o.type) && String(v).trim() !== "" && !isNaN(Number(v))) return Number(v) !== o.default;
    return String(v) !== asText(o, o.default);
  }

  // the first rule between options (in the server's order) the options ``out`` break, as the server says it:
  // { names: [the option, its partner], text }, or null
  function brokenRule(out) {
    const rules = [];
    Object.values(schema.byName).forEach((o) => (o.rules || []).forEach((r) => rules.push([o, r])));
    rules.sort((a, b) => a[1].index - b[1].index);
    const on = (name) => !!schema.byName[name] && given(schema.byName[name], out[name]);
    for (const [o, r] of rules) {
      if (!on(o.name)) continue;
      const withIt = r.others.filter(on);
      let other;
      if (r.kind === "not_with" && withIt.length) other = withIt[0];
      else if (r.kind === "needs" && !withIt.length) other = r.others.join(" or ");
      else continue;
      const text = "option '" + o.name + "' " + r.why.replace(/\{(\w+)\}/g, (m, k) => (k === "other" ? other : k));
      return { names: [o.name, ...(withIt.length ? [other] : r.others)], text: text };
    }
    return null;
  }

  // mark the fields of the options a broken rule names (none: clear the marks)
  function markBroken(names) {
    document.querySelectorAll("#options-fields [data-option]").forEach((wrap) => {
      wrap.classList.toggle("broken", names.includes(wrap.dataset.option));
    });
  }

  async function upload(file, role) {
    const fd = new FormData();
    fd.append("role", role);
    fd.append("file", file, file.name);
    return api("/api/upload", { form: fd });
  }

  async function planJob() {
    if (!page.job) return;
    await schema.ready;
    clearError();
    $("plan").disabled = true;
    $("job-summary").textContent = "planning…";
    const forced = (schema.forcedKind || {})[$("read-as").value] || $("read-as").value;
    if (forced && forced !== page.kind) { page.kind = forced; showKind(forced); }  // its options apply
    const options = collectOptions();
    const broken = brokenRule(options);
    markBroken(broken ? broken.names : []);
    try {
      if (broken) { showError(broken.text); throw new Error(broken.text); }  // not sent: the server would refuse it
      const r = await api("/api/plan", { json: { job: page.job, options: options } });
      page.planned = r;
      $("job-size").textContent = r.size_mm[0].toFixed(2) + " × " + r.size_mm[1].toFixed(2) + " mm, depth " +
        r.depth_mm.toFixed(2) + " mm";
      $("job-time").textContent = hms(r.estimated_time_s) + " (" + r.estimated_time_s.toFixed(1) + " s)";
      $("job-summary").textContent = r.summary;
      if (r.kind && r.kind !== page.kind) { page.kind = r.kind; showKind(r.kind); }  // read as another kind
      $("job-tools").textContent = r.tool_changes.length ? r.tool_changes.join("; ") : "none";
      $("job-cutter").textContent = (r.tool || "point") +
        (r.line_width_mm ? ", lines " + r.line_width_mm.toFixed(3) + " mm wide" : "");
      const img = $("preview");
      img.src = withToken(r.preview);
      img.hidden = false;
      if (!$("height-map").hidden) showHeightMap();  // the new job over the map
    } catch (e) {
      page.planned = null;
      $("job-summary").textContent = "not planned";
    } finally {
      $("plan").disabled = !page.job;
      render(page.state);
    }
  }

  $("file").addEventListener("change", async (ev) => {
    const file = ev.target.files[0];
    if (!file) return;
    clearError();
    page.job = null; page.planned = null; page.kind = null;
    $("preview").hidden = true;
    $("job-name").textContent = file.name + " – uploading…";
    try {
      const r = await upload(file, "job");
      page.job = r.job; page.kind = r.kind;
      $("job-name").textContent = r.name + " (" + r.kind + ", " + r.bytes + " bytes)";
      await schema.ready;
      showKind(r.kind);
      await planJob();
    } catch (e) {
      $("job-name").textContent = file.name + " – refused";
    } finally {
      ev.target.value = "";
      render(page.state);
    }
  });

  $("read-as").addEventListener("change", () => planJob());

  $("options-form").addEventListener("submit", (ev) => { ev.preventDefault(); planJob(); });

  // -- run controls ----------------------------------------------------------------
  function post(path, body) { clearError(); return api(path, { json: body || {} }).then(render, () => {}); }
  $("start").addEventListener("click", () => {  // a job planned elsewhere comes back planned again from here
    if (!page.planned) return;
    clearError();
    api("/api/start", { json: { job: page.planned.job } }).then((s) => {
      if (s.planned) { page.planned = s.planned; $("preview").src = withToken(s.planned.preview); }
      render(s);
    }, () => {});
  });
  $("pause").addEventListener("click", () => post("/api/pause"));
  $("resume").addEventListener("click", () => post("/api/resume"));
  $("stop").addEventListener("click", () => post("/api/stop"));
  $("resume-job").addEventListener("click", () => post("/api/resume-job"));
  $("origin").addEventListener("click", () => post("/api/origin"));
  document.querySelectorAll("button.jog").forEach((b) => b.addEventListener("click", () => {
    const n = parseInt($("jog-steps").value, 10) * parseInt(b.dataset.dir, 10);
    post("/api/jog", { axis: b.dataset.axis, steps: n, unit: $("jog-unit").value });
  }));
  $("set-offset").addEventListener("click", () => post("/api/offset"));
  document.querySelectorAll("button.zero").forEach((b) => b.addEventListener("click", () => {
    post("/api/zero", { axes: b.dataset.axes });
  }));
  $("offset-select").addEventListener("change", () => post("/api/use-offset", { offset: $("offset-select").value }));
  $("goto-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const xyz = ["x", "y", "z"].map((a) => parseFloat($("goto-" + a).value));
    post("/api/goto", { xyz: xyz, unit: "mm", machine: $("goto-machine").checked });
  });
  document.querySelectorAll("button.drill-z").forEach((b) => b.addEventListener("click", () => {
    post("/api/drill-z", { which: b.dataset.which });
  }));
  $("home").addEventListener("click", () => post("/api/home"));
  // probing (capability "probes"): the session probes, sets the work Z, writes the height map
  function plateMm() { const v = $("probe-plate").value; return v === "" ? 0 : parseFloat(v); }
  $("probe-z").addEventListener("click", () => post("/api/probe-z", { plate_mm: plateMm() }));
  $("probe-tool").addEventListener("click", () => post("/api/probe-tool", { plate_mm: plateMm() }));
  $("probe-area").addEventListener("click", () => post("/api/probe-area", {
    job: page.planned ? page.planned.job : null, spacing_mm: parseFloat($("probe-spacing").value) }));
  function showHeightMap() {
    const img = $("height-map");
    img.src = withToken("/api/height-map.png?job=" + encodeURIComponent(page.planned ? page.planned.job : "") +
                        "&v=" + Date.now());
    img.hidden = false;
    $("forget-height-map").hidden = false;
  }
  $("forget-height-map").addEventListener("click", async () => {  // the next jobs are not levelled to it
    await post("/api/forget-height-map", {});
    $("height-map").hidden = true;
    $("forget-height-map").hidden = true;
  });
  $("setpos-form").addEventListener("submit", (ev) => {  // the user's word: the position is known again
    ev.preventDefault();
    const xyz = ["x", "y", "z"].map((a) => parseFloat($("setpos-" + a).value));
    post("/api/set-position", { xyz: xyz, unit: "mm" });
  });
  $("feed-set").addEventListener("click", () => post("/api/feed-override", { percent: parseFloat($("feed-override").value) }));

  function estop() {
    const now = Date.now();
    if (now - page.estopAt < 300) return;  // pointerdown and the click after it
    page.estopAt = now;
    sendEstop(0);
  }
  function sendEstop(attempt) {
    // sent again every 50 ms until the server answers it (a busy or flooded server, a dropped connection):
    // only a refusal that another try cannot change (a 4xx other than 429) ends the tries, after 5 s at most
    api("/api/estop", { json: {} }).catch((e) => {
      const again = !e.status || e.status >= 500 || e.status === 429;
      if (again && attempt < 100) setTimeout(() => sendEstop(attempt + 1), 50);
    });
  }
  $("estop").addEventListener("pointerdown", estop);
  $("estop").addEventListener("click", estop);
  document.addEventListener("keydown", (ev) => { if (ev.key === "Escape") estop(); });

  function answer(action) {
    const p = page.state && page.state.prompt;
    $("prompt-dialog").close();
    const body = { prompt: p ? p.id : null, action: action };
    if (action === "probe-tool") body.plate_mm = plateMm();  // the plate of the row's Probe Z and Probe tool
    post("/api/answer", body);
  }
  $("prompt-continue").addEventListener("click", () => answer("continue"));
  $("prompt-probe-tool").addEventListener("click", () => answer("probe-tool"));
  $("prompt-stop").addEventListener("click", () => answer("stop"));
  $("error-close").addEventListener("click", clearError);

  // -- machine settings and tools (issue #47 points 4 and 5) -----------------------
  // The Settings section lists every key GET /api/settings gives (value, kind, unit, range, help) in a field
  // each, grouped by the machine file's tables; Save sends the fields changed, as typed: the server checks and
  // saves them.  The Tools section lists GET /api/tools and sets or removes a tool through its API.
  const machine = { settings: [] };

  function settingField(e) {
    let input;
    if (e.kind === "bool" || e.choices.length) {
      input = document.createElement("select");
      (e.kind === "bool" ? ["true", "false"] : e.choices).forEach((c) => {
        const o = document.createElement("option"); o.value = c; o.textContent = c; input.appendChild(o);
      });
    } else {
      input = document.createElement("input");
      if (e.kind !== "str") input.inputMode = "decimal";
    }
    input.name = e.key;
    input.value = e.value === null ? "" : String(e.value);
    input.dataset.was = input.value;
    const label = document.createElement("label");
    label.dataset.key = e.key;
    label.title = e.help;
    label.textContent = e.key + (e.unit ? " (" + e.unit + ")" : "") + (e.range ? " — " + e.range : "");
    label.appendChild(input);
    if (e.help) {  // a phone has no hover: the help under the field
      const help = document.createElement("small"); help.className = "muted setting-help"; help.textContent = e.help;
      label.appendChild(help);
    }
    return label;
  }

  function showSettings(r) {
    machine.settings = r.settings;
    $("settings-file").textContent = r.file + (r.exists ? "" : " (made at the first save)") + "; backup " + r.backup;
    const list = $("settings-list");
    list.textContent = "";
    const groups = {};
    r.settings.forEach((e) => {
      const table = e.key.includes(".") ? e.key.split(".")[0] : "machine";
      if (!groups[table]) {
        const d = document.createElement("details");
        d.dataset.table = table;
        const sum = document.createElement("summary");
        sum.textContent = table === "machine" ? "machine (top level)" : "[" + table + "]";
        d.appendChild(sum);
        list.appendChild(d);
        groups[table] = d;
      }
      groups[table].appendChild(settingField(e));
    });
    filterSettings();
  }

  function filterSettings() {
    const words = $("settings-filter").value.trim().toLowerCase();
    $("settings-list").querySelectorAll("label[data-key]").forEach((l) => {
      l.hidden = !!words && !l.dataset.key.toLowerCase().includes(words);
    });
    $("settings-list").querySelectorAll("details").forEach((d) => {
      if (words) d.open = !!d.querySelector("label[data-key]:not([hidden])");
    });
  }

  function loadSettings() { return api("/api/settings").then(showSettings, () => {}); }

  $("settings-filter").addEventListener("input", filterSettings);
  $("settings-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const values = {};
    $("settings-list").querySelectorAll("[name]").forEach((el) => {
      if (el.value !== el.dataset.was) values[el.name] = el.value;
    });
    if (!Object.keys(values).length) { showError("no setting changed"); return; }
    api("/api/settings", { json: { values: values } }).then((r) => { clearError(); showSettings(r); }, () => {});
  });

  function showTools(r) {
    const shape = $("tool-shape");
    if (!shape.options.length) {
      r.shapes.forEach((s) => { const o = document.createElement("option"); o.value = s; o.textContent = s; shape.appendChild(o); });
    }
    $("tools-file").textContent = r.file;
    const list = $("tools-list");
    list.textContent = "";
    if (!r.tools.length) {
      const li = document.createElement("li"); li.className = "muted"; li.textContent = "no tools yet"; list.appendChild(li);
    }
    r.tools.forEach((t) => {
      const li = document.createElement("li");
      li.dataset.number = String(t.number);
      const text = document.createElement("span"); text.textContent = t.text;
      const edit = document.createElement("button"); edit.type = "button"; edit.className = "plain tool-edit";
      edit.textContent = "✎"; edit.title = "edit T" + t.number;
      edit.addEventListener("click", () => {
        $("tool-number").value = t.number; $("tool-shape").value = t.shape; $("tool-diameter").value = t.diameter_mm;
        $("tool-angle").value = t.angle_deg; $("tool-length").value = t.length_mm === null ? "" : t.length_mm;
      });
      const del = document.createElement("button"); del.type = "button"; del.className = "plain tool-remove";
      del.textContent = "✕"; del.title = "remove T" + t.number;
      del.addEventListener("click", () => api("/api/tools/remove", { json: { number: t.number } }).then(showTools, () => {}));
      li.append(text, edit, del);
      list.appendChild(li);
    });
  }

  function loadTools() { return api("/api/tools").then(showTools, () => {}); }

  $("tool-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const body = {};
    $("tool-form").querySelectorAll("[data-field]").forEach((el) => { body[el.dataset.field] = el.value; });
    api("/api/tools", { json: body }).then((r) => { clearError(); showTools(r); }, () => {});
  });

  loadSettings();
  loadTools();


  // -- live track, the job's own units, the hole table, keyboard jog (issue #47 points 1-3 and 7) ------------------
  // The server gives the job's path and holes in machine mm (GET /api/track) and the tool where the machine reports
  // it in every snapshot; the page draws them (no plan is replayed here: the trail is the reported positions).
  const track = { key: null, data: null, trail: [], wasJob: false, holes: null, chosen: null, states: null };

  function loadTrack() {
    const p = page.planned;
    if (!p) return;
    track.key = p.preview;
    api("/api/track?job=" + encodeURIComponent(p.job)).then((t) => {
      track.data = t;
      drawTrack();
    }, () => {});
    loadHoles();
  }

  function loadHoles() {
    const p = page.planned;
    if (!p) return;
    api("/api/holes?job=" + encodeURIComponent(p.job) + "&unit=" + $("holes-unit").value).then(showHoles, () => {});
  }

  function showHoles(r) {
    track.holes = r;
    $("holes-card").hidden = !r.holes.length;
    const body = $("holes-table").querySelector("tbody");
    body.textContent = "";
    const digits = r.unit === "mil" ? 1 : r.unit === "inch" ? 4 : 3;
    r.holes.forEach((h) => {
      const tr = document.createElement("tr");
      tr.dataset.number = String(h.number);
      [h.number, "T" + h.tool + " " + h.diameter_mm.toFixed(2), h.x.toFixed(digits), h.y.toFixed(digits), h.state]
        .forEach((v) => { const td = document.createElement("td"); td.textContent = v; tr.appendChild(td); });
      tr.addEventListener("click", () => chooseHole(h.number));
      body.appendChild(tr);
    });
    $("holes-summary").textContent = r.holes.length + " holes in drilling order; X, Y in the file's own frame" +
      (r.file_units ? " (the file is in " + r.file_units + ")" : "");
    if (track.chosen && track.chosen > r.holes.length) track.chosen = null;
    if (track.states) holeStates(track.states);
    chooseHole(track.chosen);
  }

  function chooseHole(number) {
    track.chosen = number;
    $("holes-table").querySelectorAll("tbody tr").forEach((tr) => {
      tr.classList.toggle("chosen", tr.dataset.number === String(number));
    });
    const idle = page.state && page.state.state === "idle";
    $("hole-goto").disabled = !(idle && number);
    $("hole-start").disabled = !(idle && number);
    $("hole-goto").textContent = number ? "Go To hole " + number : "Go To";
    $("hole-start").textContent = number ? "Start At hole " + number : "Start At";
  }

  function holeStates(states) {
    track.states = states;
    $("holes-table").querySelectorAll("tbody tr").forEach((tr, i) => {
      const st = states[i] || "to do";
      tr.dataset.state = st;
      tr.lastChild.textContent = st;
    });
  }

  // the spindle switch (a machine with one: the MAXIMUS board)
  document.querySelectorAll("button.spindle").forEach((b) => b.addEventListener("click", () => {
    post("/api/spindle", { on: b.dataset.on === "true" });
  }));

  $("holes-unit").addEventListener("change", loadHoles);
  $("hole-goto").addEventListener("click", () => {
    if (page.planned && track.chosen) post("/api/goto-hole", { job: page.planned.job, hole: track.chosen });
  });
  $("hole-start").addEventListener("click", () => {
    if (page.planned && track.chosen) post("/api/start-at-hole", { job: page.planned.job, hole: track.chosen });
  });

  // machine steps -> picture pixels: the preview's own arithmetic, from the library (track.picture)
  function toPicture(xy) {
    const t = track.data, f = t.picture;
    return [f.origin_px[0] + f.px_per_step[0] * (xy[0] - t.home_steps[0]),
            f.origin_px[1] + f.px_per_step[1] * (xy[1] - t.home_steps[1])];
  }
  function mmToSteps(p) { return [p[0] / track.data.mm_per_step[0], p[1] / track.data.mm_per_step[1]]; }

  function drawTrack() {
    const t = track.data, canvas = $("track");
    if (!t) return;
    canvas.hidden = $("preview").hidden;
    $("track-box").hidden = canvas.hidden;
    if (canvas.width !== t.picture.width || canvas.height !== t.picture.height) {
      canvas.width = t.picture.width; canvas.height = t.picture.height;
    }
    const g = canvas.getContext("2d");
    g.clearRect(0, 0, canvas.width, canvas.height);
    g.lineCap = "round"; g.lineJoin = "round";
    g.strokeStyle = "#1f5fbf"; g.lineWidth = 3;  // what the tool cut, where the machine said it was
    track.trail.forEach((run) => {
      if (run.length < 2) return;
      g.beginPath(); run.forEach((p, i) => { const [x, y] = toPicture(p); i ? g.lineTo(x, y) : g.moveTo(x, y); });
      g.stroke();
    });
    const states = track.states || [];
    const colours = { done: "#1d7a34", drilling: "#b86100", skipped: "#9aa5b1" };
    t.holes_mm.forEach((p, i) => {
      const [x, y] = toPicture(mmToSteps(p)), st = states[i] || "to do";
      if (colours[st]) { g.beginPath(); g.arc(x, y, 4, 0, 2 * Math.PI); g.fillStyle = colours[st]; g.fill(); }
      if (track.chosen === i + 1) {
        g.beginPath(); g.arc(x, y, 9, 0, 2 * Math.PI); g.strokeStyle = "#c40000"; g.lineWidth = 2; g.stroke();
      }
    });
    const s = page.state;
    if (s) {  // the tool (kept inside the picture when it stands outside the job)
      let [x, y] = toPicture(s.position_steps);
      x = Math.min(Math.max(x, 4), canvas.width - 4); y = Math.min(Math.max(y, 4), canvas.height - 4);
      const r = 10;
      g.strokeStyle = "#c40000"; g.lineWidth = 2.5;
      g.beginPath(); g.moveTo(x - r, y); g.lineTo(x + r, y); g.moveTo(x, y - r); g.lineTo(x, y + r); g.stroke();
      g.beginPath(); g.arc(x, y, r / 2, 0, 2 * Math.PI); g.stroke();
    }
    canvas.dataset.trail = String(track.trail.reduce((n, run) => n + run.length, 0));
    canvas.dataset.tool = s ? s.position_steps.slice(0, 2).join(",") : "";
  }

  // called with every snapshot (render): the trail, the positions, the hole states, the picture
  function liveTrack(s) {
    if (page.planned && page.planned.preview !== track.key) { track.trail = []; track.states = null; loadTrack(); }
    const job = s.activity === "job";
    if (job && !track.wasJob) { track.trail = []; track.states = null; if (page.planned) loadTrack(); }  // a new run
    track.wasJob = job;
    if (job && track.data) {  // below the job's surface (+Z deeper): the tool cuts; above it a run of the trail ends
      const cutting = s.position_steps[2] > track.data.home_steps[2];
      const last = track.trail[track.trail.length - 1];
      const p = [s.position_steps[0], s.position_steps[1]];
      if (cutting) {
        if (!last || last.open !== true) { const run = [p]; run.open = true; track.trail.push(run); }
        else last.push(p);
      } else if (last) { last.open = false; }
    }
    if (s.holes && page.planned && s.holes.job === page.planned.job) holeStates(s.holes.states);
    if (s.where) $("work-steps").textContent = s.where.work_steps.join(", ");
    if (s.state === "paused" || s.state === "prompt") $("remaining").textContent += " (paused)";
    $("spindle-row").hidden = !(s.capabilities || []).includes("spindle");
    document.querySelectorAll("button.spindle").forEach((b) => { b.disabled = s.state !== "idle"; });
    $("spindle-state").textContent = "spindle: " + (s.spindle === true ? "on" : s.spindle === false ? "off" : "not known");
    $("spindle-state").dataset.on = String(s.spindle);
    const jp = s.job_position;
    if (jp && page.planned && jp.job === page.planned.job) {
      const digits = jp.unit === "px" ? 1 : jp.unit === "inch" ? 4 : 3;
      $("job-pos").textContent = jp.xyz.map((v) => v.toFixed(digits)).join(", ");
      $("job-pos-unit").textContent = jp.unit === "px" ? "pixels (the drawing's column, row, Z)" : jp.unit + " (the file's frame)";
      $("job-pos-also").textContent = jp.mil ? jp.mil.map((v) => v.toFixed(1)).join(", ") + " mil" : "";
    }
    chooseHole(track.chosen);
    drawTrack();
  }

  // keyboard jogging: arrows X and Y (as the pad: up is Y-), Page Up / Page Down Z up / down, the pad's step size;
  // refused while anything runs (the server refuses too)
  const JOG_KEYS = { ArrowLeft: ["x", -1], ArrowRight: ["x", 1], ArrowUp: ["y", -1], ArrowDown: ["y", 1],
                     PageUp: ["z", -1], PageDown: ["z", 1] };
  document.addEventListener("keydown", (ev) => {
    const key = JOG_KEYS[ev.key];
    if (!key || !$("jog-keys").checked || ev.altKey || ev.ctrlKey || ev.metaKey) return;
    const el = document.activeElement;
    if (el && (["INPUT", "SELECT", "TEXTAREA"].includes(el.tagName) && el.id !== "jog-keys" || el.isContentEditable)) return;
    ev.preventDefault();
    if (ev.repeat) return;  // one jog per key press
    if (!page.state || page.state.state !== "idle") {
      const busy = page.state ? page.state.state : "not connected";
      showError("keyboard jog refused: the machine is " + (busy === "prompt" ? "waiting at a prompt" : busy));
      return;
    }
    const n = parseInt($("jog-steps").value, 10) * key[1];
    post("/api/jog", { axis: key[0], steps: n, unit: $("jog-unit").value });
  });

  // -- live state ------------------------------------------------------------------
  function render(s) {
    if (!s || !s.state) return;
    // a reply to a request can arrive after a newer state from the event stream: never show the older one
    // (it would bring back a prompt already answered over the one now waiting)
    if (page.state && typeof s.version === "number" && s.version < page.state.version) return;
    page.state = s;
    const st = s.state;
    const badge = $("state");
    badge.textContent = st + (s.label && st !== "idle" ? ": " + s.label : "") + (s.detail ? " – " + s.detail : "");
    badge.dataset.state = st;
    $("port").textContent = "port " + s.port + (s.realtime ? "" : " (simulated)");
    const idle = st === "idle", job = s.activity === "job";
    $("start").disabled = !(idle && page.planned);
    $("pause").disabled = !(st === "running" || st === "moving");
    $("resume").disabled = st !== "paused";
    $("stop").disabled = idle;
    // after a stop, an emergency stop or a failed run, the job's journal says how far it got
    $("resume-job").disabled = !(idle && s.last && s.last.activity === "job" && s.last.journal &&
                                 ["stopped", "emergency-stopped", "error"].includes(s.last.status));
    document.querySelectorAll("button.jog, #origin, #set-offset, button.drill-z, button.zero, #goto, #offset-select, #set-position")
      .forEach((b) => { b.disabled = !idle; });
    document.querySelectorAll("button.drill-z").forEach((b) => { b.hidden = !(s.capabilities || []).includes("drill_stroke"); });
    $("grbl-row").hidden = !s.grbl;  // a grbl board: its feed override
    $("home").disabled = !idle;
    const probes = (s.capabilities || []).includes("probes");
    $("probe-row").hidden = !probes;
    document.querySelectorAll("button.probe").forEach((b) => { b.disabled = !idle; });
    $("probe-area").disabled = !(idle && page.planned);
    if (s.grbl && document.activeElement !== $("feed-override")) $("feed-override").value = s.grbl.feed_override_pct;
    const shown = job || (idle && s.last && s.last.activity === "job");
    const pct = shown ? s.progress : 0;
    $("progress-bar").value = pct;
    $("percent").textContent = (Math.round(pct * 10) / 10).toString();
    $("elapsed").textContent = hms(shown ? s.elapsed_s : 0);
    $("remaining").textContent = hms(shown ? s.remaining_s : 0);
    $("pos-steps").textContent = s.position_steps.join(", ");
    $("pos-mm").textContent = s.position_mm.map((v) => v.toFixed(3)).join(", ");
    if (s.where) {  // machine and work frames, live during every activity
      $("work-mm").textContent = s.where.work_mm.map((v) => v.toFixed(3)).join(", ");
      $("work-offset").textContent = s.where.active_offset;
      if (document.activeElement !== $("offset-select")) $("offset-select").value = s.where.active_offset;
      $("pos-known").textContent = s.where.position_known ? (s.where.homed ? "position known, homed" : "position known")
        : "POSITION UNKNOWN: " + s.where.unknown_reason;
      $("pos-known").dataset.known = s.where.position_known ? "yes" : "no";
    }
    const dlg = $("prompt-dialog");
    if (s.prompt) {
      if (page.promptShown !== s.prompt.id) {
        page.promptShown = s.prompt.id;
        $("prompt-text").textContent = s.prompt.note + " — tool at " + s.prompt.position_steps.join(", ") + " steps";
        // a tool change: Probe tool when the machine probes and Probe Z set the work Z, else why not
        $("prompt-probed").textContent = s.prompt.probed || "";
        $("prompt-probed").hidden = !s.prompt.probed;
        $("prompt-why-not").textContent = s.prompt.probe_tool_why_not ?
          "Probe tool is not offered: " + s.prompt.probe_tool_why_not : "";
        $("prompt-why-not").hidden = !s.prompt.probe_tool_why_not;
        $("prompt-probe-tool").hidden = !s.prompt.probe_tool;
        $("prompt-probe-tool").textContent = s.prompt.probed ? "Probe tool again" : "Probe tool";
        if (!dlg.open) dlg.show();
      }
    } else if (dlg.open) {
      dlg.close();
    }
    const log = $("log");
    for (const e of s.log || []) {
      if (e.seq <= page.logSeq) continue;
      page.logSeq = e.seq;
      const li = document.createElement("li");
      li.className = e.level;
      li.textContent = new Date(e.t * 1000).toLocaleTimeString() + "  " + e.text;
      if (e.text.startsWith("height map of ")) showHeightMap();  // the page's Probe the job's area wrote it
      log.prepend(li);
    }
    while (log.children.length > 200) log.removeChild(log.lastChild);
    liveTrack(s);  // the live track, the job's units, the hole table (issue #47)
  }

  function listen() {
    const es = new EventSource(withToken("/api/events"));
    es.onmessage = (ev) => { try { render(JSON.parse(ev.data)); } catch (e) { /* ignore a torn message */ } };
    es.onerror = () => {
      $("state").textContent = "offline";
      $("state").dataset.state = "offline";
    };
  }

  showKind(null);
  schema.ready = loadSchema();
  api("/api/state").then((s) => { render(s); listen(); }, () => {});
})();
