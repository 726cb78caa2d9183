// The live channel: one WebSocket to the server (the token from the page's URL, when it
// came with one; else the cookie). send(m) numbers each message (m.seq) for the replies.
// ui.js reads what comes (onmessage).
import { $, api } from "/page.js";

const token = new URLSearchParams(location.search).get("token");
export const ws = new WebSocket(`ws://${location.host}/live${token ? `?token=${encodeURIComponent(token)}` : ""}`);
ws.binaryType = "arraybuffer";
ws.addEventListener("open", (e) => { api.openMs = e.timeStamp; });
ws.onclose = () => { $("fc-status").textContent = "disconnected: the server stopped (or refused the page)"; };

let seq = 0;
export function send(m) {
  m.seq = ++seq;
  api.sentSeq = seq;
  api.sentAt[seq] = performance.now();
  ws.send(JSON.stringify(m));
  return seq;
}

export const isOpen = () => ws.readyState === WebSocket.OPEN;
