"""The round trip an integrator makes with a Python client generated from openapi.yaml
(openapi-python-client): upload OBJ, GLB and multipart meshes, submit every kind (JSON and
multipart), poll, download every format, cancel, and read problems. Run by tests/api/clients.rs
as `python python_roundtrip.py GENERATED_DIR BASE_URL FIXTURES_DIR`; exits non-zero with a
message at the first thing that does not work.
"""

import io
import json
import sys
import time

sys.path.insert(0, sys.argv[1])
BASE, FIXTURES = sys.argv[2], sys.argv[3]

from flatmesh_client import Client  # noqa: E402
from flatmesh_client.api.default import (  # noqa: E402
    cancel_job,
    get_job,
    get_mesh,
    job_mesh,
    job_patterns,
    job_result,
    list_jobs,
    list_meshes,
    submit_job,
    upload_mesh,
)
from flatmesh_client import models as m  # noqa: E402
from flatmesh_client.types import File  # noqa: E402

client = Client(base_url=BASE, raise_on_unexpected_status=True, timeout=120)


def fixture(name):
    with open(f"{FIXTURES}/{name}", "rb") as f:
        return f.read()


def check(cond, what):
    if not cond:
        sys.exit(f"python client: {what}")


def upload(data, fmt):
    r = upload_mesh.sync_detailed(client=client, body=File(payload=io.BytesIO(data)), format_=fmt)
    check(r.status_code in (200, 201), f"upload {fmt}: {r.status_code} {r.content[:300]!r}")
    check(isinstance(r.parsed, m.Mesh), f"upload {fmt} parsed as {type(r.parsed)}")
    return r.parsed


def wait(job_id, want=("succeeded",)):
    t = time.time()
    while True:
        j = get_job.sync(job_id, client=client)
        check(isinstance(j, m.Job), f"get_job parsed as {type(j)}")
        if j.status.value in ("succeeded", "failed", "cancelled"):
            check(j.status.value in want, f"job {j.kind.value} ended {j.status.value}: {j.error}")
            return j
        check(time.time() - t < 120, f"job {job_id} did not end")
        time.sleep(0.1)


cyl = upload(fixture("cylinder.obj"), m.UploadMeshFormat.OBJ)
check(cyl.faces > 0 and cyl.links.self_.startswith(BASE), f"mesh links: {cyl.links}")
check(get_mesh.sync(cyl.id, client=client).id == cyl.id, "get_mesh")

# Every kind through the JSON body.
requests = {
    "report": m.ReportJobRequest(kind=m.ReportJobRequestKind.REPORT, mesh_id=cyl.id),
    "flatten": m.FlattenJobRequest(
        kind=m.FlattenJobRequestKind.FLATTEN,
        mesh_id=cyl.id,
        params=m.FlattenParams(unit=m.FlattenParamsUnit.CM),
    ),
    "fl-mesh": m.FlMeshJobRequest(kind=m.FlMeshJobRequestKind.FL_MESH, mesh_id=cyl.id),
    "subdivide": m.SubdivideJobRequest(
        kind=m.SubdivideJobRequestKind.SUBDIVIDE, mesh_id=cyl.id, params=m.SubdivideParams(levels=1)
    ),
    "develop": m.DevelopJobRequest(kind=m.DevelopJobRequestKind.DEVELOP, mesh_id=cyl.id),
    "segment": m.SegmentJobRequest(kind=m.SegmentJobRequestKind.SEGMENT, mesh_id=cyl.id),
}
done = {}
for kind, body in requests.items():
    r = submit_job.sync_detailed(client=client, body=body)
    check(r.status_code == 202, f"submit {kind}: {r.status_code} {r.content[:300]!r}")
    check(r.headers["location"].startswith(BASE), f"absolute Location: {r.headers['location']}")
    done[kind] = wait(r.parsed.id)
    check(done[kind].kind.value == kind, f"kind {done[kind].kind}")

# Perturb with its reference body, and a report, through multipart.
body = m.SubmitJobFilesBody(
    job=m.PerturbMultipartJob(
        kind=m.PerturbMultipartJobKind.PERTURB, params=m.PerturbParams(clearance=0.0)
    ),
    mesh=File(payload=io.BytesIO(fixture("cylinder_noisy.obj")), file_name="garment.obj", mime_type="model/obj"),
    reference=File(payload=io.BytesIO(fixture("cylinder.obj")), file_name="body.obj", mime_type="model/obj"),
)
r = submit_job.sync_detailed(client=client, body=body)
check(r.status_code == 202, f"multipart perturb: {r.status_code} {r.content[:300]!r}")
done["perturb"] = wait(r.parsed.id)

# Results: the report model, every mesh and pattern format as bytes.
rep = job_result.sync(done["flatten"].id, client=client)
check(isinstance(rep, m.Report) and rep.faces == cyl.faces, f"result parsed as {type(rep)}")
for fmt, magic in [(m.JobMeshFormat.GLB, b"glTF"), (m.JobMeshFormat.GLTF, b"{"), (m.JobMeshFormat.OBJ, b"")]:
    f = job_mesh.sync(done["fl-mesh"].id, client=client, format_=fmt)
    check(isinstance(f, File), f"mesh {fmt.value} parsed as {type(f)}")
    data = f.payload.read()
    check(len(data) > 100 and data.startswith(magic), f"mesh {fmt.value}: {data[:20]!r}")
    if fmt == m.JobMeshFormat.GLB:
        glb = data
for fmt, magic in [(m.JobPatternsFormat.JSON, b"{"), (m.JobPatternsFormat.SVG, b"<"), (m.JobPatternsFormat.DXF, b"")]:
    f = job_patterns.sync(done["flatten"].id, client=client, format_=fmt)
    check(isinstance(f, File), f"patterns {fmt.value} parsed as {type(f)}")
    data = f.payload.read()
    check(len(data) > 100 and data.lstrip().startswith(magic), f"patterns {fmt.value}: {data[:20]!r}")
    if fmt == m.JobPatternsFormat.JSON:
        check("pieces" in json.loads(data), "patterns JSON")

# A GLB we produced goes back in as an upload (raw and multipart).
g = upload(glb, m.UploadMeshFormat.GLB)
check(g.format_ == "glb" and g.faces == cyl.faces, f"GLB upload: {g.format_} {g.faces}")
r = upload_mesh.sync_detailed(
    client=client,
    body=m.UploadMeshFilesBody(mesh=File(payload=io.BytesIO(fixture("cone.obj")), file_name="cone.obj")),
)
check(r.status_code in (200, 201) and isinstance(r.parsed, m.Mesh), f"multipart upload: {r.status_code}")

# Listings.
jobs = list_jobs.sync(client=client, page_size=2)
check(isinstance(jobs, m.JobList) and len(jobs.jobs) == 2 and jobs.next_page_token, "list_jobs")
more = list_jobs.sync(client=client, page_size=100, page_token=jobs.next_page_token)
check(len(more.jobs) >= 5, f"second page: {len(more.jobs)}")
meshes = list_meshes.sync(client=client)
check(isinstance(meshes, m.MeshList) and len(meshes.meshes) >= 3, "list_meshes")

# Cancel a long job (a 120 × 120 saddle that flatten cannot satisfy), twice.
n = 120
rows = [f"v {i / n:.6f} {j / n:.6f} {0.3 * ((i / n) ** 2 - (j / n) ** 2):.6f}" for j in range(n + 1) for i in range(n + 1)]
for j in range(n):
    for i in range(n):
        a = j * (n + 1) + i + 1
        rows += [f"f {a} {a + 1} {a + n + 2}", f"f {a} {a + n + 2} {a + n + 1}"]
saddle = upload("\n".join(rows).encode(), m.UploadMeshFormat.OBJ)
slow = m.FlattenJobRequest(
    kind=m.FlattenJobRequestKind.FLATTEN,
    mesh_id=saddle.id,
    params=m.FlattenParams(tolerance=1e-300, max_iterations=100_000),
)
j = submit_job.sync(client=client, body=slow)
r = cancel_job.sync_detailed(j.id, client=client)
check(r.status_code == 202, f"cancel: {r.status_code}")
c = wait(j.id, want=("cancelled",))
check(c.error is not None and c.error.type_.endswith("/problems/cancelled"), f"cancelled error: {c.error}")
r = cancel_job.sync_detailed(j.id, client=client)
check(r.status_code == 200 and isinstance(r.parsed, m.Job), f"second cancel: {r.status_code}")

# Problems come back typed.
p = get_job.sync("j_nope", client=client)
check(isinstance(p, m.Problem) and p.status == 404, f"404 parsed as {type(p)}")
bad = m.SubdivideJobRequest(
    kind=m.SubdivideJobRequestKind.SUBDIVIDE, mesh_id=cyl.id, params=m.SubdivideParams(levels=99)
)
p = submit_job.sync(client=client, body=bad)
check(isinstance(p, m.Problem) and p.status == 422 and p.field == "params.levels", f"422: {p}")
print("python client round trip: ok")
