// Validates the Indexed Jobs deploy/k8s/farm/plan-to-jobs wrote for a plan, offline: each
// against the Kubernetes API schema (kubernetes-models), then that the stages cover the plan's
// tasks in order, one pod index per task, each running `cloudbake run-task` on the shared folder.
// Usage: node farm.cjs JOBS_DIR PLAN_JSON. Exits 1 on any failure.
'use strict';
const fs = require('fs');
const path = require('path');
const batch = require('kubernetes-models/batch/v1');

const [dir, planFile] = process.argv.slice(2);
const plan = JSON.parse(fs.readFileSync(planFile, 'utf8'));
const failures = [];
const check = (ok, what) => {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures.push(what);
};

const files = fs.readdirSync(dir).filter((f) => f.endsWith('.json')).sort();
const covered = [];
for (const file of files) {
  const job = JSON.parse(fs.readFileSync(path.join(dir, file), 'utf8'));
  try {
    new batch.Job(job).validate();
    check(true, `${file}: Job ${job.metadata.name} matches the API schema`);
  } catch (e) {
    check(false, `${file}: ${e.message}`);
    continue;
  }
  const spec = job.spec;
  const script = spec.template.spec.containers[0].command.join(' ');
  const ids = (script.match(/ids=\(([^)]*)\)/) || ['', ''])[1].split(' ').filter(Boolean);
  check(spec.completionMode === 'Indexed' && spec.completions === ids.length,
        `${file}: one pod index per task (${ids.length})`);
  check(script.includes('cloudbake run-task') && script.includes('$JOB_COMPLETION_INDEX'),
        `${file}: pod i runs run-task for task i`);
  check(spec.template.spec.volumes.some((v) => v.persistentVolumeClaim),
        `${file}: mounts the shared folder`);
  covered.push(...ids);
}
check(JSON.stringify(covered) === JSON.stringify(plan.tasks.map((t) => t.id)),
      `the stages run the plan's ${plan.tasks.length} tasks, in the plan's order`);
if (failures.length) process.exit(1);
