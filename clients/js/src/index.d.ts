export * from './errors.js';
export * from './frame.js';
export * from './api.js';
export { SessionSocket, RECONNECT_CODES, RESEND_CODES, shouldReconnect } from './session.js';
export type { DragDelta, SocketOptions, SocketEvents, SocketStats, StateEvent, ServerEvent, CloseInfo } from './session.js';
/** The WebSocket protocol version this client speaks. */
export const PROTOCOL_VERSION: 3;
