// <choreo-player src="…/motion.glb" audio="…/audio">: the page's 3-D player as a custom element,
// for any page. One classic script (`/assets/choreo-player.js`, three.js bundled in) defines it.
//
// Like the page, it never keeps time itself: each display frame reads the song's audio clock
// (the <audio> element's currentTime) and shows the dance's pose at that time, so the dance cannot
// drift from the music. `audioTime` and `animationTime` are the two clocks as last drawn, for
// checks: they agree within one motion frame (1/25 s).
//
// Attributes: src (a job's motion.glb), audio (its song), api-key (sent as
// `Authorization: Bearer <key>` with both; the song is then fetched and played from a blob URL,
// since an <audio> element cannot send headers), view ('figure' or 'sticks'), nocontrols.
// Events: `choreo-load` (detail: {duration}) once both are loaded, `choreo-error` (detail: the Error)
// when either fails or the song cannot be played; the element then says what went wrong inside
// itself (part="error"), with a hint where the browser hides the cause (a refused cross-origin
// request reads only as a failed fetch).
import { Stage } from './player.js';

const STYLE = `
:host { display: block; position: relative; width: 100%; height: 360px; min-height: 120px; }
:host([hidden]) { display: none; }
.wrap { display: flex; flex-direction: column; width: 100%; height: 100%; }
.stage { flex: 1; min-height: 0; }
.stage canvas { display: block; }
.error { position: absolute; inset: 12px 12px auto 12px; padding: 8px 10px; border-radius: 4px;
  background: #fff4f0; color: #8a1f0a; border: 1px solid #e0b4a8; font: 13px/1.4 system-ui, sans-serif; }
.error[hidden] { display: none; }
audio { width: 100%; display: block; }
:host([nocontrols]) audio { display: none; }
`;

export class ChoreoPlayer extends HTMLElement {
  static observedAttributes = ['src', 'audio', 'api-key', 'view'];

  #stage = null;
  #audio;
  #container;
  #frame = 0;
  #dirty = true;
  #animationTime = 0;
  #renderedFrames = 0;
  #frameMs = 0;
  #blobUrl = null;
  #loading = 0; // counts loads, so an older one that ends late does not overwrite a newer one
  #ready = null;
  #error;

  constructor() {
    super();
    const root = this.attachShadow({ mode: 'open' });
    root.innerHTML = `<style>${STYLE}</style><div class="wrap"><div class="stage" part="stage"></div><audio part="audio" controls preload="auto"></audio></div><div class="error" part="error" role="alert" hidden></div>`;
    this.#container = root.querySelector('.stage');
    this.#audio = root.querySelector('audio');
    this.#error = root.querySelector('.error');
    this.#audio.addEventListener('seeked', () => { this.#dirty = true; });
    this.#audio.addEventListener('error', () => {
      // A failed load of the dance already said why; this is the song's own failure.
      if (this.#error.hidden) this.#fail(this.#songError());
    });
    this.#ready = Promise.resolve();
  }

  connectedCallback() {
    if (!this.#stage) {
      this.#stage = new Stage(this.#container);
      this.#stage.controls.addEventListener('change', () => { this.#dirty = true; });
      this.#load();
    }
    const tick = () => {
      this.#draw();
      this.#frame = requestAnimationFrame(tick);
    };
    this.#frame = requestAnimationFrame(tick);
  }

  disconnectedCallback() {
    cancelAnimationFrame(this.#frame);
    this.#audio.pause();
  }

  attributeChangedCallback(name, before, after) {
    if (before === after || !this.#stage) return;
    if (name === 'view') this.#stage.setView(after || 'figure');
    else this.#load();
  }

  /** One display frame: the audio clock sets the dance's time; nothing else keeps time. */
  #draw() {
    if (!this.#stage?.action || !(this.#dirty || !this.#audio.paused)) return;
    const started = performance.now();
    this.#animationTime = this.#stage.setTime(this.#audio.currentTime);
    this.#stage.render();
    this.#renderedFrames++;
    this.#dirty = false;
    this.#frameMs = performance.now() - started;
  }

  #headers() {
    const key = this.getAttribute('api-key');
    return key ? { Authorization: `Bearer ${key}` } : {};
  }

  /** Shows `error` inside the element and fires `choreo-error`. */
  #fail(error) {
    this.#error.textContent = String(error.message ?? error);
    this.#error.hidden = false;
    this.dispatchEvent(new CustomEvent('choreo-error', { detail: error }));
  }

  async #fetch(url) {
    let response;
    try {
      response = await fetch(url, { headers: this.#headers() });
    } catch (cause) {
      // The browser tells a page no more than "failed to fetch" for a server that is down and
      // for one that does not allow this page's origin (CORS): name both.
      throw new Error(`could not load ${url}: the server did not answer, or it does not allow requests from ${location.origin} (add that origin to the server's cors_origins)`, { cause });
    }
    if (!response.ok) {
      let detail = '';
      try { detail = (await response.json()).detail ?? ''; } catch { /* not problem+json */ }
      throw new Error(`${url}: HTTP ${response.status}${detail ? `: ${detail}` : ''}`);
    }
    return response;
  }

  #load() {
    const load = ++this.#loading;
    this.#error.hidden = true;
    const src = this.getAttribute('src');
    const audio = this.getAttribute('audio');
    this.#ready = (async () => {
      const [glb, song] = await Promise.all([
        src ? this.#fetch(src).then((r) => r.arrayBuffer()) : null,
        // With a key the song is fetched (headers); without one the browser streams it itself.
        audio && this.getAttribute('api-key') ? this.#fetch(audio).then((r) => r.blob()) : audio,
      ]);
      if (load !== this.#loading) return;
      if (this.#blobUrl) URL.revokeObjectURL(this.#blobUrl);
      this.#blobUrl = song instanceof Blob ? URL.createObjectURL(song) : null;
      const metadata = song ? this.#songMetadata() : null;
      if (song) this.#audio.src = this.#blobUrl ?? song;
      else this.#audio.removeAttribute('src');
      // The song counts as loaded once the browser knows its length: a keyless song is streamed
      // by the <audio> itself, and seeking or playing before then would start it from 0.
      await metadata;
      if (load !== this.#loading) return;
      if (glb) {
        await this.#stage.load(glb);
        this.#stage.setView(this.getAttribute('view') || 'figure');
      } else {
        this.#stage.clear();
      }
      this.#dirty = true;
      this.dispatchEvent(new CustomEvent('choreo-load', { detail: { duration: this.duration } }));
    })().catch((error) => {
      // A song the <audio> could not play has already said so (its error listener).
      if (load === this.#loading && this.#error.hidden) this.#fail(error);
      throw error;
    });
    this.#ready.catch(() => {}); // reported by the event; `loaded` rejects for whoever awaits it
  }

  /** Resolves when the <audio> has read the new song's metadata; rejects on a media error. */
  #songMetadata() {
    return new Promise((resolve, reject) => {
      const done = () => { this.#audio.removeEventListener('loadedmetadata', ok); this.#audio.removeEventListener('error', bad); };
      const ok = () => { done(); resolve(); };
      const bad = () => {
        done();
        reject(this.#songError());
      };
      this.#audio.addEventListener('loadedmetadata', ok);
      this.#audio.addEventListener('error', bad);
    });
  }

  /** What the <audio>'s media error says, with the song it could not play. */
  #songError() {
    return new Error(`the song could not be played (media error ${this.#audio.error?.code ?? '?'}): ${this.getAttribute('audio')}`);
  }

  /** Resolves when the dance and the song named now are loaded; rejects when either failed. */
  get loaded() { return this.#ready; }
  /** The song's position, seconds (the audio element's currentTime). */
  get audioTime() { return this.#audio.currentTime; }
  /** The time of the pose on screen, seconds (the animation's time at the last drawn frame). */
  get animationTime() { return this.#animationTime; }
  /** The dance's length, seconds. */
  get duration() { return this.#stage?.duration ?? 0; }
  get playing() { return !this.#audio.paused; }
  /** Frames drawn since the element was created. */
  get renderedFrames() { return this.#renderedFrames; }
  /** How long the last drawn frame took, milliseconds (from reading the audio clock to the end). */
  get frameMs() { return this.#frameMs; }
  /** The <audio> element that keeps time (volume, muted, events). */
  get audio() { return this.#audio; }
  /** A joint's world position (metres), as drawn. */
  joint(name) { return this.#stage?.joint(name) ?? null; }
  /** Where a joint is drawn in the view ([x, y], −1…1 inside it), or null: the camera follows the
   * dancer, so the body centre stays near [0, 0] wherever the dance travels. */
  onScreen(name) { return this.#stage?.onScreen(name) ?? null; }
  /** What the element shows as its error now, or null. */
  get error() { return this.#error.hidden ? null : this.#error.textContent; }
  play() { return this.#audio.play(); }
  pause() { this.#audio.pause(); }
  seek(t) {
    this.#audio.currentTime = Math.max(0, Math.min(t, this.#audio.duration || t));
    this.#dirty = true;
  }
}

if (!customElements.get('choreo-player')) customElements.define('choreo-player', ChoreoPlayer);
