// validate.mjs — offline validation of kdray's Kubernetes manifests.
//
//   node tests/k8s/validate.mjs FILE.yaml...          validate
//   node tests/k8s/validate.mjs --self-test FILE.yaml  + broken copies
//
// Each document is checked against the Kubernetes API schema of its
// apiVersion and kind by the npm package kubernetes-models (schemas
// generated from the Kubernetes OpenAPI spec: types, formats, required
// fields, enums), installed from npm by ./scripts/dev deps into
// tests/k8s/node_modules; nothing is fetched here. Those schemas allow
// unknown fields, so the checks below add what a typo or a rename would
// break: selectors that select the pod template, probes on kdrayd's
// endpoints and on a declared port, requests and limits, volume mounts
// and claims that exist, the Service and the HPA aimed at the Deployment.
// --self-test also breaks copies of the manifests in known ways and fails
// unless each broken copy is rejected.
import { readFileSync } from "node:fs";
import { parseAllDocuments } from "yaml";

async function modelClass(apiVersion, kind) {
    // core "v1" lives at kubernetes-models/v1/..., others at GROUP/VERSION
    const path = `kubernetes-models/${apiVersion}/${kind}`;
    try {
        const mod = await import(path);
        return mod[kind] || mod.default;
    } catch (e) {
        if (e.code === "ERR_MODULE_NOT_FOUND" && !String(e.message).includes(kind))
            throw new Error("kubernetes-models is not installed: run ./scripts/dev deps");
        return null;
    }
}

function load(file) {
    const docs = parseAllDocuments(readFileSync(file, "utf8"));
    const out = [];
    for (const d of docs) {
        if (d.errors.length) throw new Error(`${file}: YAML: ${d.errors[0].message}`);
        const obj = d.toJS();
        if (obj !== null && obj !== undefined) out.push(obj);
    }
    return out;
}

function labelsMatch(selector, labels) {
    return Object.entries(selector || {}).every(([k, v]) => (labels || {})[k] === v) &&
           Object.keys(selector || {}).length > 0;
}

// Project rules across documents; returns a list of problems.
function crossChecks(docs) {
    const bad = [];
    const byKind = (k) => docs.filter((d) => d.kind === k);
    const claims = new Set(byKind("PersistentVolumeClaim").map((d) => d.metadata.name));
    const deployments = byKind("Deployment");
    if (deployments.length === 0) bad.push("no Deployment");
    for (const d of deployments) {
        const n = `Deployment ${d.metadata.name}`;
        const tpl = d.spec.template;
        if (!labelsMatch(d.spec.selector.matchLabels, tpl.metadata && tpl.metadata.labels))
            bad.push(`${n}: selector does not select its pod template`);
        const volumes = new Map((tpl.spec.volumes || []).map((v) => [v.name, v]));
        for (const v of volumes.values())
            if (v.persistentVolumeClaim && !claims.has(v.persistentVolumeClaim.claimName))
                bad.push(`${n}: volume ${v.name} claims an undeclared PVC`);
        const kdrayd = tpl.spec.containers.find((c) => c.name === "kdrayd");
        if (!kdrayd) {
            bad.push(`${n}: no container named kdrayd`);
            continue;
        }
        const ports = new Set((kdrayd.ports || []).flatMap((p) => [p.name, p.containerPort]));
        const probe = (name, path) => {
            const p = kdrayd[name];
            if (!p || !p.httpGet) return bad.push(`${n}: no ${name} (httpGet)`);
            if (p.httpGet.path !== path) bad.push(`${n}: ${name} is not on ${path}`);
            if (!ports.has(p.httpGet.port)) bad.push(`${n}: ${name} port is not a container port`);
        };
        probe("readinessProbe", "/v1/ready");
        probe("livenessProbe", "/v1/health");
        const r = kdrayd.resources || {};
        for (const k of ["requests", "limits"])
            for (const res of ["cpu", "memory"])
                if (!(r[k] && r[k][res])) bad.push(`${n}: no ${k}.${res}`);
        for (const m of kdrayd.volumeMounts || [])
            if (!volumes.has(m.name)) bad.push(`${n}: mount ${m.name} names no volume`);
        const args = (kdrayd.args || []).join(" ");
        const cache = /--cache-dir[= ](\S+)/.exec(args);
        if (!cache) bad.push(`${n}: kdrayd has no --cache-dir`);
        else if (!(kdrayd.volumeMounts || []).some((m) => m.mountPath === cache[1]))
            bad.push(`${n}: --cache-dir ${cache[1]} is not on a volume`);
        const listen = /--listen[= ]\S+:(\d+)/.exec(args);
        if (!listen || !ports.has(Number(listen[1])))
            bad.push(`${n}: --listen port is not the container port`);
        for (const s of byKind("Service"))
            if (!labelsMatch(s.spec.selector, tpl.metadata.labels))
                bad.push(`Service ${s.metadata.name}: selects no pod of ${n}`);
    }
    const hpas = byKind("HorizontalPodAutoscaler");
    if (hpas.length === 0) bad.push("no HorizontalPodAutoscaler");
    for (const h of hpas) {
        const t = h.spec.scaleTargetRef;
        if (!deployments.some((d) => t.kind === "Deployment" && t.name === d.metadata.name))
            bad.push(`HorizontalPodAutoscaler ${h.metadata.name}: targets no Deployment here`);
        if (!(h.spec.metrics || []).some((m) => m.type === "Resource" && m.resource.name === "cpu"))
            bad.push(`HorizontalPodAutoscaler ${h.metadata.name}: does not scale on CPU`);
    }
    if (byKind("Service").length === 0) bad.push("no Service");
    return bad;
}

// All problems of a set of documents (schema, then cross checks).
async function problems(docs) {
    const bad = [];
    for (const d of docs) {
        const what = `${d.kind} ${d.metadata && d.metadata.name}`;
        const Cls = await modelClass(d.apiVersion, d.kind);
        if (!Cls) {
            bad.push(`${what}: unknown apiVersion/kind ${d.apiVersion}/${d.kind}`);
            continue;
        }
        try {
            new Cls(d).validate();
        } catch (e) {
            bad.push(`${what}: ${String(e.message).split("\n")[0]}`);
        }
    }
    if (bad.length) return bad;
    return crossChecks(docs);
}

// Broken copies: each must be rejected, by the schema or the cross checks.
const BREAKS = [
    ["replicas as a string", (ds) => { dep(ds).spec.replicas = "two"; }],
    ["container without a name", (ds) => { delete kd(ds).name; }],
    ["probe period as a string", (ds) => { kd(ds).readinessProbe.periodSeconds = "2s"; }],
    ["HPA metric type misspelled", (ds) => { hpa(ds).spec.metrics[0].type = "Cpu"; }],
    ["Service port given as a name", (ds) => { svc(ds).spec.ports[0].port = "http"; }],
    ["Deployment selector off the template", (ds) => {
        dep(ds).spec.selector.matchLabels = { app: "other" }; }],
    ["readiness on the wrong path", (ds) => { kd(ds).readinessProbe.httpGet.path = "/ready"; }],
    ["liveness on an undeclared port", (ds) => { kd(ds).livenessProbe.httpGet.port = "web"; }],
    ["no memory limit", (ds) => { delete kd(ds).resources.limits.memory; }],
    ["mount of a missing volume", (ds) => { kd(ds).volumeMounts[1].name = "cache"; }],
    ["cache dir on no volume", (ds) => {
        kd(ds).args = kd(ds).args.map((a) => a.replace(/--cache-dir=\S+/, "--cache-dir=/tmp/c"));
    }],
    ["HPA aimed elsewhere", (ds) => { hpa(ds).spec.scaleTargetRef.name = "kdray-old"; }],
    ["Service selecting nothing", (ds) => { svc(ds).spec.selector = { app: "x" }; }],
    ["unknown kind", (ds) => { svc(ds).kind = "Servce"; }],
];
const dep = (ds) => ds.find((d) => d.kind === "Deployment");
const kd = (ds) => dep(ds).spec.template.spec.containers[0];
const hpa = (ds) => ds.find((d) => d.kind === "HorizontalPodAutoscaler");
const svc = (ds) => ds.find((d) => d.kind === "Service");

async function main(argv) {
    const selfTest = argv.includes("--self-test");
    const files = argv.filter((a) => a !== "--self-test");
    if (files.length === 0) {
        console.error("usage: validate.mjs [--self-test] FILE.yaml...");
        return 2;
    }
    let failed = 0;
    const all = [];
    for (const f of files) {
        const docs = load(f);
        all.push(...docs);
        console.log(`${f}: ${docs.map((d) => d.kind).join(", ")}`);
    }
    const bad = await problems(all);
    for (const b of bad) console.log(`FAIL ${b}`);
    failed += bad.length;
    if (!bad.length) console.log(`ok   ${all.length} documents valid`);
    if (selfTest) {
        for (const [what, breakIt] of BREAKS) {
            const copy = structuredClone(all);
            breakIt(copy);
            const found = await problems(copy);
            if (found.length) console.log(`ok   broken (${what}) rejected: ${found[0]}`);
            else {
                console.log(`FAIL broken (${what}) was accepted`);
                failed++;
            }
        }
    }
    console.log(failed ? `${failed} problems` : "all checks passed");
    return failed ? 1 : 0;
}

try {
    process.exitCode = await main(process.argv.slice(2));
} catch (e) {
    console.error(`validate.mjs: ${e.message}`);
    process.exitCode = 1;
}
