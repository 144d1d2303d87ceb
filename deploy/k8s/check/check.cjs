// Validates deploy/k8s/base offline: every object against the Kubernetes API schema
// (kubernetes-models), then what the schema cannot know about cloudbake-server. Usage:
//   node check.cjs K8S_BASE_DIR SERVER_HELP_FILE SERVER_VERSION
// Prints one line per check; exits 1 on the first list of failures.
'use strict';
const fs = require('fs');
const path = require('path');
const yaml = require('js-yaml');
const core = require('kubernetes-models/v1');
const apps = require('kubernetes-models/apps/v1');

const [dir, helpFile, version] = process.argv.slice(2);
const failures = [];
const check = (ok, what) => {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
};

const models = {'v1/ConfigMap': core.ConfigMap, 'v1/Service': core.Service,
                'apps/v1/StatefulSet': apps.StatefulSet};
const kustomization = yaml.load(fs.readFileSync(path.join(dir, 'kustomization.yaml'), 'utf8'));
const files = fs.readdirSync(dir).filter((f) => f.endsWith('.yaml') && f !== 'kustomization.yaml');
check(JSON.stringify([...kustomization.resources].sort()) === JSON.stringify([...files].sort()),
      `kustomization.yaml lists every manifest (${files.join(', ')})`);

const objects = {};
for (const file of files) {
  for (const doc of yaml.loadAll(fs.readFileSync(path.join(dir, file), 'utf8'))) {
    const key = `${doc.apiVersion}/${doc.kind}`;
    const Model = models[key];
    if (!Model) {
      check(false, `${file}: ${key} has no validator here (add it to check.cjs)`);
      continue;
    }
    try {
      new Model(doc).validate();
      check(true, `${file}: ${doc.kind} ${doc.metadata.name} matches the API schema`);
    } catch (e) {
      check(false, `${file}: ${doc.kind} ${doc.metadata.name}: ${e.message}`);
    }
    objects[`${doc.kind}/${doc.metadata.name}`] = doc;
  }
}
if (failures.length) process.exit(1);

const sts = objects['StatefulSet/cloudbake'];
const config = objects['ConfigMap/cloudbake-config'].data;
const pod = sts.spec.template.spec;
const container = pod.containers.find((c) => c.name === 'cloudbake-server');
const portOf = (name) => (container.ports.find((p) => p.name === name) || {}).containerPort;
const listenPort = (v) => Number(String(v).split(':').pop());
const help = fs.readFileSync(helpFile, 'utf8');

for (const name of Object.keys(config)) {
  check(help.includes(`(Env:${name})`), `ConfigMap ${name} is a variable cloudbake-server --help lists`);
}
check(container.envFrom.some((e) => e.configMapRef && e.configMapRef.name === 'cloudbake-config'),
      'the container takes its flags from the ConfigMap');
check(listenPort(config.CLOUDBAKE_LISTEN) === portOf('grpc'),
      `the server listens (${config.CLOUDBAKE_LISTEN}) on the grpc container port ${portOf('grpc')}`);
check(listenPort(config.CLOUDBAKE_METRICS_LISTEN) === portOf('metrics'),
      'the metrics endpoint listens on the metrics container port');
for (const probe of ['startupProbe', 'livenessProbe', 'readinessProbe']) {
  const p = container[probe];
  check(p && p.grpc && p.grpc.port === portOf('grpc') && !p.grpc.service,
        `${probe} calls the standard gRPC health service on the server's port`);
}
const annotations = sts.spec.template.metadata.annotations || {};
check(Number(annotations['prometheus.io/port']) === portOf('metrics'),
      'the Prometheus scrape annotation names the metrics port');
const [image, tag] = container.image.split(':');
check(image.split('/').pop() === 'cloudbake' && tag === version,
      `the image is cloudbake:${version} (the server's --version)`);
check(String(container.resources.limits.cpu) === config.CLOUDBAKE_THREADS &&
      String(container.resources.requests.cpu) === config.CLOUDBAKE_THREADS,
      'CPU request and limit equal CLOUDBAKE_THREADS');
check(config.CLOUDBAKE_MAX_CONCURRENT_JOBS === '1' ||
      Number(config.CLOUDBAKE_THREADS) % Number(config.CLOUDBAKE_MAX_CONCURRENT_JOBS) === 0,
      'concurrent jobs share the CPU limit');
const grace = sts.spec.template.spec.terminationGracePeriodSeconds;
check(grace >= 10 && grace <= 60, `terminationGracePeriodSeconds ${grace} covers the server's drain (about 3 s)`);
const dockerfile = fs.readFileSync(path.join(dir, '..', '..', '..', 'Dockerfile'), 'utf8');
const imageUser = Number((dockerfile.match(/^USER (\d+)/m) || [])[1]);
const imageState = (dockerfile.match(/CLOUDBAKE_CACHE_DIR=(\S+)/) || [])[1];
const sc = {...pod.securityContext, ...container.securityContext};
check(sc.runAsNonRoot === true && sc.runAsUser === imageUser && sc.readOnlyRootFilesystem === true &&
      sc.allowPrivilegeEscalation === false,
      `non-root (uid ${imageUser}, the Dockerfile's USER), read-only root, no privilege escalation`);
check(config.CLOUDBAKE_CACHE_DIR === imageState,
      `the state folder is the image's volume (${imageState})`);
const mounts = Object.fromEntries(container.volumeMounts.map((m) => [m.mountPath, m.name]));
check(mounts[config.CLOUDBAKE_CACHE_DIR] === 'state' &&
      sts.spec.volumeClaimTemplates.some((t) => t.metadata.name === 'state'),
      'CLOUDBAKE_CACHE_DIR is the mounted PersistentVolumeClaim');
check(mounts['/tmp'] && pod.volumes.some((v) => v.name === mounts['/tmp'] && v.emptyDir),
      'a writable /tmp (emptyDir) under the read-only root');
const labels = sts.spec.template.metadata.labels;
check(Object.entries(sts.spec.selector.matchLabels).every(([k, v]) => labels[k] === v),
      'the StatefulSet selector matches its pods');
for (const svc of ['Service/cloudbake', 'Service/cloudbake-headless']) {
  const s = objects[svc];
  check(Object.entries(s.spec.selector).every(([k, v]) => labels[k] === v),
        `${svc} selects the server's pods`);
  for (const p of s.spec.ports) {
    check(portOf(p.targetPort) !== undefined, `${svc} port ${p.name} targets a container port`);
  }
}
check(objects['Service/cloudbake-headless'].spec.clusterIP === 'None' &&
      sts.spec.serviceName === 'cloudbake-headless', 'the headless Service governs the StatefulSet');
if (failures.length) {
  console.error(`k8s check: ${failures.length} failure(s)`);
  process.exit(1);
}
console.log('k8s check: passed');
