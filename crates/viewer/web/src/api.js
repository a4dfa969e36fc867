// How the page talks to its server. Both servers (`motionaug view` and the
// coordinator) describe every clip with the URLs of its parts (meta, frames,
// flags, report), so the player does not care which one it talks to. The
// service needs the tenant's API key on every request (Authorization header);
// local mode has no key.

let apiKey = null;

export function setKey(key) {
  apiKey = key;
}

function headers() {
  return apiKey ? { Authorization: `Bearer ${apiKey}` } : {};
}

export class HttpError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

async function checked(url, init = {}) {
  const response = await fetch(url, { ...init, headers: { ...headers(), ...(init.headers || {}) } });
  if (!response.ok) {
    let detail = response.statusText;
    try {
      const body = await response.json();
      detail = body.detail || body.title || detail;
    } catch (_) {
      // not JSON
    }
    throw new HttpError(response.status, `${url}: ${response.status} ${detail}`);
  }
  return response;
}

export async function json(url) {
  return (await checked(url)).json();
}

export async function binary(url) {
  return (await checked(url)).arrayBuffer();
}

/// Downloads `url` (which needs the key) as a file: the name the server
/// gives (Content-Disposition), else `name`.
export async function download(url, name) {
  const response = await checked(url);
  const given = /filename="([^"]+)"/.exec(response.headers.get("content-disposition") || "");
  if (given) name = given[1];
  const blob = await response.blob();
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = name;
  document.body.appendChild(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 10000);
}

/// Follows a server-sent event stream with fetch (EventSource cannot send the
/// key): calls `onEvent(name, data)` per event until the stream ends or
/// `signal` aborts. Returns when the stream ends.
export async function followEvents(url, onEvent, signal) {
  const response = await checked(url, { signal, headers: { Accept: "text/event-stream" } });
  const reader = response.body.getReader();
  const decoder = new TextDecoder();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += decoder.decode(value, { stream: true });
    let end;
    while ((end = buffer.indexOf("\n\n")) >= 0) {
      const block = buffer.slice(0, end);
      buffer = buffer.slice(end + 2);
      let name = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) name = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).trimStart());
      }
      if (data.length) onEvent(name, data.join("\n"));
    }
  }
}
