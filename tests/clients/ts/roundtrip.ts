// The round trip an integrator makes with a TypeScript client generated from openapi.yaml
// (openapi-typescript types, openapi-fetch at run time): type-checked by tsc, then run by
// tests/api/clients.rs as `node out/roundtrip.js BASE_URL FIXTURES_DIR`. Exits non-zero with a
// message at the first thing that does not work.
import fs from "node:fs";
import createClient from "openapi-fetch";
import type { components, paths } from "./schema.js";

type Job = components["schemas"]["Job"];
const [BASE, FIXTURES] = process.argv.slice(2);
const client = createClient<paths>({ baseUrl: BASE });

function check(cond: unknown, what: string): asserts cond {
  if (!cond) {
    console.error(`typescript client: ${what}`);
    process.exit(1);
  }
}

const fixture = (name: string) => new Blob([fs.readFileSync(`${FIXTURES}/${name}`)]);

async function upload(body: Blob, format: "obj" | "glb") {
  const { data, response } = await client.POST("/v1/meshes", {
    params: { query: { format } },
    body,
    bodySerializer: (b) => b,
    headers: { "content-type": "application/octet-stream" },
  });
  check(data, `upload ${format}: ${response.status}`);
  return data;
}

async function wait(id: string, want: Job["status"][] = ["succeeded"]): Promise<Job> {
  const start = Date.now();
  for (;;) {
    const { data } = await client.GET("/v1/jobs/{id}", { params: { path: { id } } });
    check(data, `poll ${id}`);
    if (["succeeded", "failed", "cancelled"].includes(data.status)) {
      check(want.includes(data.status), `${data.kind} ended ${data.status}: ${JSON.stringify(data.error)}`);
      return data;
    }
    check(Date.now() - start < 120_000, `job ${id} did not end`);
    await new Promise((r) => setTimeout(r, 100));
  }
}

const cyl = await upload(fixture("cylinder.obj"), "obj");
check(cyl.links.self.startsWith(BASE), `absolute links: ${cyl.links.self}`);

// Every kind but perturb as JSON; the request type is the discriminated union.
const requests: components["schemas"]["JobRequest"][] = [
  { kind: "report", mesh_id: cyl.id },
  { kind: "flatten", mesh_id: cyl.id, params: { unit: "cm" } },
  { kind: "fl-mesh", mesh_id: cyl.id },
  { kind: "subdivide", mesh_id: cyl.id, params: { levels: 1 } },
  { kind: "develop", mesh_id: cyl.id },
  { kind: "segment", mesh_id: cyl.id },
];
const done: Record<string, Job> = {};
for (const body of requests) {
  const { data, response } = await client.POST("/v1/jobs", { body });
  check(data, `submit ${body.kind}: ${response.status}`);
  check(response.headers.get("location")?.startsWith(BASE), "absolute Location");
  done[body.kind] = await wait(data.id);
}

// Perturb with its reference body, through multipart.
const form = new FormData();
form.append("job", new Blob([JSON.stringify({ kind: "perturb", params: { clearance: 0 } })], { type: "application/json" }));
form.append("mesh", fixture("cylinder_noisy.obj"), "garment.obj");
form.append("reference", fixture("cylinder.obj"), "body.obj");
{
  const { data, response } = await client.POST("/v1/jobs", {
    body: form as unknown as never,
    bodySerializer: () => form,
  });
  check(data, `multipart perturb: ${response.status}`);
  done.perturb = await wait(data.id);
}

// Results: the typed report; every mesh and pattern format as bytes or text.
const { data: report } = await client.GET("/v1/jobs/{id}/result", { params: { path: { id: done.flatten.id } } });
check(report && report.faces === cyl.faces, "result");
let glb: ArrayBuffer | undefined;
for (const format of ["glb", "gltf", "obj"] as const) {
  const { data, response } = await client.GET("/v1/jobs/{id}/mesh", {
    params: { path: { id: done["fl-mesh"].id }, query: { format } },
    parseAs: "arrayBuffer",
  });
  check(data && data.byteLength > 100, `mesh ${format}: ${response.status}`);
  if (format === "glb") {
    check(new TextDecoder().decode(data.slice(0, 4)) === "glTF", "GLB magic");
    glb = data;
  }
}
for (const format of ["json", "svg", "dxf"] as const) {
  const { data, response } = await client.GET("/v1/jobs/{id}/patterns", {
    params: { path: { id: done.flatten.id }, query: { format } },
    parseAs: "text",
  });
  check(typeof data === "string" && data.length > 100, `patterns ${format}: ${response.status}`);
  if (format === "json") check("pieces" in JSON.parse(data), "patterns JSON");
  if (format === "svg") check(data.includes("<svg"), "SVG");
}

// The GLB goes back in.
check(glb, "no GLB");
const again = await upload(new Blob([glb]), "glb");
check(again.format === "glb" && again.faces === cyl.faces, `GLB upload: ${again.format}`);

// Listings and paging.
const { data: page } = await client.GET("/v1/jobs", { params: { query: { page_size: 2 } } });
check(page && page.jobs.length === 2 && page.next_page_token, "list_jobs");
const { data: meshes } = await client.GET("/v1/meshes");
check(meshes && meshes.meshes.length >= 2, "list_meshes");

// Cancel a job, twice.
const n = 120;
const rows: string[] = [];
for (let j = 0; j <= n; j++)
  for (let i = 0; i <= n; i++) rows.push(`v ${i / n} ${j / n} ${0.3 * ((i / n) ** 2 - (j / n) ** 2)}`);
for (let j = 0; j < n; j++)
  for (let i = 0; i < n; i++) {
    const a = j * (n + 1) + i + 1;
    rows.push(`f ${a} ${a + 1} ${a + n + 2}`, `f ${a} ${a + n + 2} ${a + n + 1}`);
  }
const saddle = await upload(new Blob([rows.join("\n")]), "obj");
const { data: slow } = await client.POST("/v1/jobs", {
  body: { kind: "flatten", mesh_id: saddle.id, params: { tolerance: 1e-300, max_iterations: 100000 } },
});
check(slow, "slow submit");
const first = await client.POST("/v1/jobs/{id}/cancel", { params: { path: { id: slow.id } } });
check(first.response.status === 202, `cancel: ${first.response.status}`);
const cancelled = await wait(slow.id, ["cancelled"]);
check(cancelled.error?.type.endsWith("/problems/cancelled"), "cancelled error");
const second = await client.POST("/v1/jobs/{id}/cancel", { params: { path: { id: slow.id } } });
check(second.response.status === 200 && second.data?.status === "cancelled", "second cancel");

// Problems, typed.
const missing = await client.GET("/v1/jobs/{id}", { params: { path: { id: "j_nope" } } });
check(missing.error?.status === 404, "404 problem");
const bad = await client.POST("/v1/jobs", { body: { kind: "subdivide", mesh_id: cyl.id, params: { levels: 99 } } });
check(bad.error?.status === 422 && bad.error.field === "params.levels", "422 problem");
console.log("typescript client round trip: ok");
