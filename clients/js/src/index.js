// dend-client: the JavaScript client of the dend deformation server.
// HTTP routes (api.js), the session WebSocket (session.js), pose frame
// decoders (frame.js) and typed errors (errors.js); the three.js binding
// is the separate entry point `dend-client/three`.

export * from './errors.js';
export * from './frame.js';
export * from './api.js';
export { SessionSocket, RECONNECT_CODES, RESEND_CODES, shouldReconnect } from './session.js';

/** The WebSocket protocol version this client speaks (api/ws-protocol.md). */
export const PROTOCOL_VERSION = 3;
