// Browser tests of `bite studio`, in Debian's chromium driven by
// playwright-core. Run by crates/bite-cli/tests/studio.rs:
//
//   node studio.mjs SCENARIO URL SHOTS_DIR [ARG]
//
// Each scenario drives the page as a user would and exits 0 when what it
// checks holds, 1 (with the reason) when not. Screenshots go to SHOTS_DIR.
import { chromium } from "playwright-core";
import { join } from "node:path";

const [scenario, url, shots, arg] = process.argv.slice(2);
const executablePath = process.env.BITE_CHROMIUM || "/usr/bin/chromium";

function fail(why) {
  console.error(`FAIL (${scenario}): ${why}`);
  process.exitCode = 1;
  throw new Error(why);
}

async function until(what, fn, timeoutMs = 30000) {
  const end = Date.now() + timeoutMs;
  let last;
  while (Date.now() < end) {
    last = await fn();
    if (last) return last;
    await new Promise((r) => setTimeout(r, 100));
  }
  fail(`timed out waiting for ${what}`);
}

const browser = await chromium.launch({
  executablePath,
  headless: true,
  args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync"],
});
const page = await browser.newPage({ viewport: { width: 1600, height: 1000 } });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
const shot = (name) => page.screenshot({ path: join(shots, `${name}.png`) });

// Robots' stacks as the monitor shows them: name → leaf behavior.
const stacks = () => page.$$eval("#robots tbody tr", (rows) =>
  Object.fromEntries(rows.map((r) => [r.dataset.robot, r.querySelector(".stack")?.textContent ?? ""])));

try {
  await page.goto(url);
  await page.waitForSelector("#commands li[data-name=find]");
  await page.waitForFunction(() => window.studio?.cm);

  if (scenario === "editor") {
    // A mission with a misspelled command: the diagnostic at its line,
    // with the did-you-mean.
    await page.selectOption("#kind", "rtcl");
    await page.evaluate(() => window.studio.cm.setValue(""));
    await page.click(".CodeMirror");
    await page.keyboard.type("find::::yellow=>box\nmvoe:box:-.5:.5\n");
    const d = await until("a diagnostic on line 2", () =>
      page.$eval("#diagnostics", (ul) => {
        const li = [...ul.querySelectorAll("li.diagnostic")].find((l) => l.dataset.line === "2");
        return li ? li.textContent : null;
      }));
    if (!/did you mean `move`/.test(d)) fail(`no did-you-mean in: ${d}`);
    if (!d.startsWith("2:1")) fail(`not at 2:1: ${d}`);
    // The lint marker in the editor's gutter, on line 2.
    await until("a lint marker", () => page.$(".CodeMirror-lint-marker-error"));
    await shot("studio-diagnostics");
    // Drag `find` from the sidebar onto line 2: its template goes there.
    const cm = await page.$(".CodeMirror");
    const box = await cm.boundingBox();
    const at = await page.evaluate(() => {
      const c = window.studio.cm.charCoords({ line: 1, ch: 3 }, "window");
      return { x: c.left, y: (c.top + c.bottom) / 2 };
    });
    await page.dragAndDrop("#commands li[data-name=find]", ".CodeMirror", {
      targetPosition: { x: at.x - box.x, y: at.y - box.y },
    });
    const template = await page.$eval("#commands li[data-name=find]", (l) => l.dataset.template);
    const line2 = await page.evaluate(() => window.studio.cm.getLine(1));
    if (line2 !== template) fail(`line 2 is \`${line2}\`, not the template \`${template}\``);
    const line3 = await page.evaluate(() => window.studio.cm.getLine(2));
    if (!line3.startsWith("mvoe")) fail(`the old line 2 did not move down: \`${line3}\``);
    // Fix the typo: the diagnostics clear and the graph is drawn.
    await page.evaluate((template) => {
      const cm = window.studio.cm;
      cm.setValue(cm.getValue().replace("mvoe", "move").replace(template + "\n", ""));
    }, template);
    await until("no errors", () => page.$("#diagnostics li.ok"));
    await until("the graph", () => page.$("#graph svg g.behavior"));
    const points = await page.$$eval("#points tbody tr", (r) => r.length);
    if (points < 1) fail("no coordination points listed");
    await shot("studio-editor");
    console.log(`ok: diagnostic "${d.replace(/\n/g, " ")}", drop gave \`${line2}\`, ${points} points`);
  } else if (scenario === "run") {
    // Run the opened mission: the three robots' stacks change, it completes.
    await until("the graph", () => page.$("#graph svg g.behavior"));
    await page.selectOption("#pace", arg || "5");
    await page.click("#run");
    const seen = new Map();
    await until("the run to complete", async () => {
      const s = await stacks();
      for (const [r, st] of Object.entries(s)) {
        if (!seen.has(r)) seen.set(r, new Set());
        seen.get(r).add(st);
      }
      const out = await page.$eval("#outcome", (e) => e.textContent);
      if (seen.size >= 1 && [...seen.values()].some((v) => v.size >= 2) && !seen.has("__shot")) {
        await shot("studio-run");
        seen.set("__shot", new Set());
      }
      return out.startsWith("completed") ? out : null;
    }, 120000);
    seen.delete("__shot");
    if (seen.size !== 3) fail(`expected three robots, saw ${[...seen.keys()]}`);
    for (const [r, v] of seen) if (v.size < 2) fail(`${r}'s stack never changed: ${[...v]}`);
    const drawn = await page.evaluate(() => {
      const c = document.querySelector("#arena");
      const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
      let ink = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i + 3] > 0) ink++;
      return { ink, robots: window.studio.stats.frames };
    });
    if (drawn.ink < 100) fail("the arena is empty");
    const decisions = await page.$$eval("#timeline circle.decision", (c) => c.length);
    if (decisions < 1) fail("no decisions on the timeline");
    await shot("studio-monitor");
    console.log(`ok: ${seen.size} robots, stacks seen ${[...seen.values()].map((v) => v.size)}, ${decisions} decisions`);
  } else if (scenario === "team") {
    // A live Zenoh team: its robots appear with their stacks.
    const want = Number(arg || 3);
    const s = await until(`${want} robots with stacks`, async () => {
      const s = await stacks();
      const withStack = Object.entries(s).filter(([, st]) => st && st !== "idle");
      return withStack.length >= want ? s : null;
    }, 60000);
    const source = await page.$eval("#source", (e) => e.textContent);
    if (!source.startsWith("zenoh")) fail(`source is ${source}`);
    // The simulator server's world: the layout (asked for, as the studio
    // joined late) and the bodies' poses.
    await until("the arena with the robots", () => page.evaluate((want) => {
      const p = Object.values(window.studio.positions()).filter(Boolean);
      return p.length >= want && window.studio.hasLayout();
    }, want), 30000);
    await shot("studio-team");
    console.log(`ok: ${Object.keys(s).join(", ")} over ${source}`);
  } else if (scenario === "replay") {
    // Open a run log; moving the scrubber moves the robots.
    if (arg) await page.setInputFiles("#open-log", arg);
    await until("the replay", () => page.$eval("#source", (e) => e.textContent.startsWith("replay")));
    const poses = () => page.evaluate(() => {
      const rows = [...document.querySelectorAll("#robots tbody tr")].map((r) => r.dataset.robot);
      return rows.length;
    });
    await until("robots", poses);
    const end = Number(await page.$eval("#scrubber", (e) => e.max));
    const at = async (t) => {
      await page.$eval("#scrubber", (e, t) => {
        e.value = t;
        e.dispatchEvent(new Event("input"));
      }, t);
      await until(`the clock at ${t}`, () => page.$eval("#clock", (e, t) => {
        const shown = parseFloat(e.textContent.replace("t = ", ""));
        return Math.abs(shown - t) < 1.0;
      }, t));
      await page.waitForTimeout(200);
      return page.evaluate(() => window.studio.positions());
    };
    const early = await at(end * 0.1);
    const late = await at(end * 0.8);
    let moved = 0;
    for (const [r, p] of Object.entries(early)) {
      const q = late[r];
      if (p && q && Math.hypot(p[0] - q[0], p[1] - q[1]) > 0.2) moved++;
    }
    if (moved < 1) fail(`no robot moved between ${early} and ${late}`);
    await shot("studio-replay");
    const back = await at(end * 0.1);
    for (const [r, p] of Object.entries(early)) {
      const q = back[r];
      if (Math.hypot(p[0] - q[0], p[1] - q[1]) > 1e-6) fail(`${r} not back where it was`);
    }
    console.log(`ok: ${moved} robots moved between ${(end * 0.1).toFixed(1)} s and ${(end * 0.8).toFixed(1)} s, and back`);
  } else if (scenario === "rate") {
    // How smooth the monitor is: snapshots received and frames drawn per
    // second while a run goes (a measurement, printed, not asserted).
    await page.selectOption("#pace", arg || "1");
    await page.click("#run");
    await until("robots moving", () => page.evaluate(() => document.querySelectorAll("#robots tbody tr").length > 0));
    await page.waitForTimeout(2000);
    const a = await page.evaluate(() => ({ ...window.studio.stats, now: performance.now() }));
    await page.waitForTimeout(10000);
    const b = await page.evaluate(() => ({ ...window.studio.stats, now: performance.now() }));
    const secs = (b.now - a.now) / 1000;
    const robots = await page.$$eval("#robots tbody tr", (r) => r.length);
    await shot("studio-100");
    const per = (x) => +(x / Math.max(1, b.snapshots - a.snapshots)).toFixed(2);
    const drawMs = Object.fromEntries(Object.keys(b.drawMs).map((k) => [k, per(b.drawMs[k] - (a.drawMs[k] || 0))]));
    console.log(JSON.stringify({
      robots, seconds: +secs.toFixed(2),
      kbytes_per_snapshot: +((b.bytes - a.bytes) / 1024 / Math.max(1, b.snapshots - a.snapshots)).toFixed(1),
      apply_ms_per_snapshot: per(b.applyMs - a.applyMs), draw_ms_per_frame: drawMs,
      snapshots_per_s: +((b.snapshots - a.snapshots) / secs).toFixed(1),
      frames_per_s: +((b.frames - a.frames) / secs).toFixed(1),
    }));
  } else {
    fail(`no scenario ${scenario}`);
  }
} catch (e) {
  if (!process.exitCode) console.error(`FAIL (${scenario}): ${e.stack || e}`);
  process.exitCode = 1;
} finally {
  await browser.close();
}
