import type { BufferGeometry, Camera, EventDispatcher, Mesh, Vector3 } from 'three';
import type { SessionSocket, DecodedFrame, HandleRef } from '../index.js';

/** A BufferGeometry of a mesh, with vertex normals. */
export function geometryFromMesh(positions: ArrayLike<number> | ArrayLike<ArrayLike<number>>, triangles: ArrayLike<number> | ArrayLike<ArrayLike<number>>): BufferGeometry;

/** vertex → handle index (-1: none) of handles given as index lists. */
export function handleIndexOf(vertexCount: number, handles: { vertices: number[] }[]): Int32Array;

export interface SessionGeometryEvents {
  dendframe: { frame: DecodedFrame; coarse: boolean };
}

/** Follows a socket's frames into a geometry in place. */
export class SessionGeometry extends EventDispatcher<SessionGeometryEvents> {
  constructor(socket: SessionSocket, geometry: BufferGeometry, options?: { normals?: boolean });
  readonly socket: SessionSocket;
  readonly geometry: BufferGeometry;
  /** Whether the last frame applied is a coarse preview. */
  readonly coarse: boolean;
  readonly frame: DecodedFrame | null;
  readonly updates: number;
  readonly mismatches: number;
  apply(frame: DecodedFrame): boolean;
  dispose(): void;
}

export interface HandleDragEvents {
  dragstart: { handle: HandleRef; point: Vector3 };
  drag: { handle: HandleRef; translate: [number, number, number]; seq: number };
  dragend: { handle: HandleRef };
  hoveron: { handle: HandleRef };
  hoveroff: { handle: HandleRef };
}

/** Drags a session's handles with the pointer. */
export class HandleDragControls extends EventDispatcher<HandleDragEvents> {
  constructor(
    socket: SessionSocket,
    object: Mesh,
    camera: Camera,
    domElement: HTMLElement,
    options?: { handleOf?: ArrayLike<number> | ((vertex: number) => HandleRef | null | undefined) },
  );
  enabled: boolean;
  /** The handle being dragged, or null. */
  readonly active: HandleRef | null;
  pick(event: PointerEvent): { handle: HandleRef; vertex: number; point: Vector3 } | null;
  dispose(): void;
}
