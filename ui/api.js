// The public HTTP API (proto/openapi.yaml), as the viewer uses it. Every
// call sends the bearer token kept in sessionStorage (the tab's session:
// not shared with other tabs, gone when the tab closes).

const TOKEN_KEY = 'raysweep.token';

export function getToken() {
  return sessionStorage.getItem(TOKEN_KEY) || '';
}

export function setToken(t) {
  if (t) sessionStorage.setItem(TOKEN_KEY, t);
  else sessionStorage.removeItem(TOKEN_KEY);
}

// An answer other than 2xx: status, the problem's code and detail.
export class ApiError extends Error {
  constructor(status, problem) {
    const detail = (problem && (problem.detail || problem.title)) || `HTTP ${status}`;
    super(detail);
    this.status = status;
    this.code = (problem && problem.code) || '';
    this.problem = problem || {};
  }
}

function headers(extra) {
  const h = Object.assign({}, extra);
  const t = getToken();
  if (t) h.Authorization = 'Bearer ' + t;
  return h;
}

async function fail(res) {
  let problem = null;
  try {
    problem = await res.json();
  } catch (e) {
    problem = null;
  }
  return new ApiError(res.status, problem);
}

// method, path; opts.body (sent as JSON), opts.headers. Resolves to
// {data, res} (data: the parsed JSON body, or null), rejects with ApiError.
export async function api(method, path, opts = {}) {
  const h = headers(opts.headers);
  let body;
  if (opts.body !== undefined) {
    h['Content-Type'] = 'application/json';
    body = JSON.stringify(opts.body);
  }
  const res = await fetch(path, { method, headers: h, body, cache: 'no-store', signal: opts.signal });
  if (!res.ok) throw await fail(res);
  const type = res.headers.get('Content-Type') || '';
  const data = res.status !== 204 && type.includes('json') ? await res.json() : null;
  return { data, res };
}

// Server-sent events of a job (GET /v1/jobs/{id}/events) through fetch,
// since EventSource cannot send an Authorization header. onEvent({event,
// id, data}) per event (data parsed as JSON). Reconnects with
// Last-Event-ID after a dropped connection until the `end` event or
// signal aborts. Resolves when the stream ends.
export async function followEvents(path, onEvent, signal) {
  let lastId = '';
  let ended = false;
  let failures = 0;
  while (!ended && !(signal && signal.aborted)) {
    let res;
    try {
      const h = headers({ Accept: 'text/event-stream' });
      if (lastId) h['Last-Event-ID'] = lastId;
      res = await fetch(path, { headers: h, cache: 'no-store', signal });
    } catch (e) {
      if (signal && signal.aborted) return;
      if (++failures > 5) throw e;
      await new Promise((r) => setTimeout(r, 500 * failures));
      continue;
    }
    if (!res.ok) throw await fail(res);
    const reader = res.body.getReader();
    const dec = new TextDecoder();
    let buf = '';
    let ev = { event: 'message', id: '', data: [] };
    let got = 0;
    const dispatch = () => {
      if (ev.data.length) {
        got++;
        if (ev.id) lastId = ev.id;
        let data = ev.data.join('\n');
        try {
          data = JSON.parse(data);
        } catch (e) {
          /* keep the text */
        }
        if (ev.event === 'end') ended = true;
        onEvent({ event: ev.event, id: ev.id, data });
      }
      ev = { event: 'message', id: '', data: [] };
    };
    try {
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buf += dec.decode(value, { stream: true });
        let m;
        while ((m = /\r\n|\r|\n/.exec(buf))) {
          const line = buf.slice(0, m.index);
          buf = buf.slice(m.index + m[0].length);
          if (line === '') dispatch();
          else if (line[0] === ':') continue; // keep-alive comment
          else {
            const i = line.indexOf(':');
            const field = i < 0 ? line : line.slice(0, i);
            let val = i < 0 ? '' : line.slice(i + 1);
            if (val[0] === ' ') val = val.slice(1);
            if (field === 'event') ev.event = val;
            else if (field === 'id') ev.id = val;
            else if (field === 'data') ev.data.push(val);
          }
        }
      }
      // A stream that closed with nothing in it (a job already over, a
      // proxy): try again a few times, then give up.
      if (got) failures = 0;
      else if (!ended && ++failures > 5) return;
      else if (!ended) await new Promise((r) => setTimeout(r, 500 * failures));
    } catch (e) {
      if (signal && signal.aborted) return;
      if (++failures > 5) throw e;
      await new Promise((r) => setTimeout(r, 500 * failures));
    }
  }
}
